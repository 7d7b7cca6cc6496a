// The wire schema is the spec's: every field number of HIP-0083's messages is checked here so
// that a change that would break wire compatibility fails a test.

#include <string>
#include <utility>
#include <vector>

#include <google/protobuf/descriptor.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/v1/service.grpc.pb.h"
#include "hanzo/fusion/v1/service.pb.h"

namespace hanzo::fusion {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;

void expect_fields(const Descriptor* descriptor, const std::vector<std::pair<std::string, int>>& fields) {
  ASSERT_NE(descriptor, nullptr);
  for (const auto& [name, number] : fields) {
    const FieldDescriptor* field = descriptor->FindFieldByName(name);
    ASSERT_NE(field, nullptr) << descriptor->full_name() << " lacks " << name;
    EXPECT_EQ(field->number(), number) << descriptor->full_name() << "." << name;
  }
}

TEST(Schema, SensorMessagesHaveTheSpecsFieldNumbers) {
  expect_fields(v1::ImuMessage::descriptor(), {{"timestamp_ns", 1}, {"frame_id", 2}, {"linear_acceleration", 3},
                                               {"angular_velocity", 4}, {"acceleration_covariance", 5},
                                               {"gyroscope_covariance", 6}, {"orientation", 7}, {"orientation_covariance", 8}});
  expect_fields(v1::PointCloudMessage::descriptor(), {{"timestamp_ns", 1}, {"frame_id", 2}, {"points", 3}, {"intensities", 4},
                                                      {"ring_ids", 5}, {"point_timestamps", 6}});
  expect_fields(v1::ImageMessage::descriptor(), {{"timestamp_ns", 1}, {"frame_id", 2}, {"width", 3}, {"height", 4},
                                                 {"encoding", 5}, {"data", 6}, {"intrinsics", 7}, {"distortion", 8}});
  expect_fields(v1::GnssMessage::descriptor(), {{"timestamp_ns", 1}, {"latitude", 2}, {"longitude", 3}, {"altitude", 4},
                                                {"fix_type", 5}, {"position_covariance", 6}, {"satellites_used", 7}, {"hdop", 8}});
  expect_fields(v1::WheelOdometryMessage::descriptor(), {{"timestamp_ns", 1}, {"frame_id", 2}, {"left_distance", 3},
                                                         {"right_distance", 4}, {"wheel_separation", 5}, {"wheel_radius", 6}});
  expect_fields(v1::RadarMessage::descriptor(), {{"timestamp_ns", 1}, {"frame_id", 2}, {"targets", 3}});
  expect_fields(v1::RadarTarget::descriptor(), {{"range", 1}, {"azimuth", 2}, {"elevation", 3}, {"radial_velocity", 4}, {"rcs", 5}});
  EXPECT_EQ(v1::ImuMessage::descriptor()->file()->package(), "hanzo.fusion.v1");
  // The packed point extension (not in the spec) is a packed float field.
  const FieldDescriptor* packed = v1::PointCloudMessage::descriptor()->FindFieldByName("packed_points");
  ASSERT_NE(packed, nullptr);
  EXPECT_EQ(packed->number(), 7);
  EXPECT_TRUE(packed->is_packed());
  EXPECT_EQ(packed->type(), FieldDescriptor::TYPE_FLOAT);
  // So is the point-time offset extension, fixed-width signed.
  const FieldDescriptor* offsets = v1::PointCloudMessage::descriptor()->FindFieldByName("point_time_offsets_ns");
  ASSERT_NE(offsets, nullptr);
  EXPECT_EQ(offsets->number(), 8);
  EXPECT_TRUE(offsets->is_packed());
  EXPECT_EQ(offsets->type(), FieldDescriptor::TYPE_SFIXED32);
  // The IMU orientation extension has explicit presence.
  EXPECT_TRUE(v1::ImuMessage::descriptor()->FindFieldByName("orientation")->has_presence());
}

TEST(Schema, GnssFixTypesAreTheSpecs) {
  const auto* fix = v1::GnssFixType_descriptor();
  const std::vector<std::string> names = {"NO_FIX", "FIX_2D", "FIX_3D", "RTK_FLOAT", "RTK_FIXED"};
  ASSERT_EQ(fix->value_count(), static_cast<int>(names.size()));
  for (int i = 0; i < fix->value_count(); ++i) EXPECT_EQ(fix->value(i)->name(), names[i]);
}

TEST(Schema, FusionServiceHasTheSpecsRpcs) {
  const auto* service = v1::SessionId::descriptor()->file()->FindServiceByName("FusionService");
  ASSERT_NE(service, nullptr);
  struct Rpc {
    std::string name, input, output;
    bool client_streaming, server_streaming;
  };
  const std::vector<Rpc> rpcs = {
      {"StreamImu", "ImuMessage", "PoseEstimate", true, true},
      {"StreamPointCloud", "PointCloudMessage", "PoseEstimate", true, true},
      {"StreamImage", "ImageMessage", "PoseEstimate", true, true},
      {"StreamGnss", "GnssMessage", "PoseEstimate", true, true},
      {"StreamRadar", "RadarMessage", "PoseEstimate", true, true},
      {"StreamRange", "RangeMessage", "PoseEstimate", true, true},
      {"StreamDetections", "DetectionsMessage", "PoseEstimate", true, true},
      {"StreamWheelOdometry", "WheelOdometryMessage", "PoseEstimate", true, true},
      {"SubscribePose", "SessionId", "PoseEstimate", false, true},
      {"SubscribeMap", "SessionId", "MapUpdate", false, true},
      {"SubscribeKeyframes", "SessionId", "Keyframe", false, true},
      {"GetMap", "MapRequest", "FusionMap", false, false},
      {"LoadMap", "FusionMap", "LoadMapResponse", false, false},
  };
  EXPECT_EQ(service->method_count(), static_cast<int>(rpcs.size()));
  for (const Rpc& rpc : rpcs) {
    const auto* method = service->FindMethodByName(rpc.name);
    ASSERT_NE(method, nullptr) << rpc.name;
    EXPECT_EQ(method->input_type()->name(), rpc.input) << rpc.name;
    EXPECT_EQ(method->output_type()->name(), rpc.output) << rpc.name;
    EXPECT_EQ(method->client_streaming(), rpc.client_streaming) << rpc.name;
    EXPECT_EQ(method->server_streaming(), rpc.server_streaming) << rpc.name;
  }
  // The generated gRPC stub exists and links.
  EXPECT_STREQ(v1::FusionService::service_full_name(), "hanzo.fusion.v1.FusionService");
}

TEST(Schema, FusionMapCarriesAFormatVersion) {
  expect_fields(v1::FusionMap::descriptor(), {{"format_version", 1}, {"map_id", 2}, {"version", 3}});
}

}  // namespace
}  // namespace hanzo::fusion
