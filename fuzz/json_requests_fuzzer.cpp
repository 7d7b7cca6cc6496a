// Fuzz target: the REST API's JSON request decoders and the YAML documents they carry (the
// fusion configuration and calibration a POST /v1/sessions body holds). Any input must give a
// value or an error, never a crash, a hang or undefined behaviour. (The YAML parsers on raw
// text are text_formats' job.)

#include <cstddef>
#include <cstdint>
#include <string>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "json_codec.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  const std::string body(reinterpret_cast<const char*>(data), size);
  if (auto request = service::detail::parse_create_session(body)) {
    (void)config::parse_fusion_config(request.value().config_yaml, "fuzz config");
    if (!request.value().calibration_yaml.empty()) (void)calib::parse_calibration(request.value().calibration_yaml, "fuzz calibration");
  }
  (void)service::detail::parse_sensor_registration(body);
  return 0;
}
