// Fuzz target: the protobuf sensor messages a gRPC Stream* call decodes (msgs/convert.hpp) and
// the validation every message passes before fusion. The first byte picks the message type,
// the rest is the wire encoding. Any input must be decoded or refused without a crash; a
// message that decodes and validates must survive an exact round trip through the wire type.

#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include <google/protobuf/stubs/logging.h>

#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/msgs/validate.hpp"

namespace {

template <typename Proto>
void decode(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  Proto wire;
  if (!wire.ParseFromArray(data, static_cast<int>(size))) return;
  auto message = msgs::from_proto(wire);
  if (!message || !msgs::validate(message.value())) return;
  // Round trip: to the wire type and back gives the same wire encoding.
  const Proto again = msgs::to_proto(message.value());
  auto decoded = msgs::from_proto(again);
  if (!decoded) std::abort();
  if (msgs::to_proto(decoded.value()).SerializeAsString() != again.SerializeAsString()) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  namespace v1 = hanzo::fusion::v1;
  // Invalid UTF-8 in string fields is a refused message, not news: keep protobuf quiet.
  static const bool quiet = [] {
    google::protobuf::SetLogHandler(nullptr);
    return true;
  }();
  (void)quiet;
  if (size == 0) return 0;
  const uint8_t* wire = data + 1;
  const size_t wire_size = size - 1;
  switch (data[0] % 6) {
    case 0: decode<v1::ImuMessage>(wire, wire_size); break;
    case 1: decode<v1::PointCloudMessage>(wire, wire_size); break;
    case 2: decode<v1::ImageMessage>(wire, wire_size); break;
    case 3: decode<v1::GnssMessage>(wire, wire_size); break;
    case 4: decode<v1::WheelOdometryMessage>(wire, wire_size); break;
    default: decode<v1::RadarMessage>(wire, wire_size); break;
  }
  return 0;
}
