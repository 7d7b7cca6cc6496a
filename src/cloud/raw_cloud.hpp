#pragma once
// Internal to cloud/: a file's points as the file lays them out (named fields at byte offsets
// within fixed-size, point-major records), between the PCD/PLY parsers and PointCloud.

#include <cstdint>
#include <string>
#include <vector>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::cloud {

enum class ScalarType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kInt64, kUint64, kFloat32, kFloat64 };

size_t scalar_size(ScalarType type);
bool is_integer(ScalarType type);
/// Writes `value` converted to `type` at `at` (text values into binary records).
void store_scalar(ScalarType type, double value, uint8_t* at);

struct RawField {
  std::string name;
  ScalarType type = ScalarType::kFloat32;
  size_t offset = 0;  // bytes within a record
};

struct RawCloud {
  std::vector<RawField> fields;
  size_t record_size = 0;   // bytes
  size_t count = 0;         // records
  std::vector<uint8_t> bytes;  // count * record_size, little-endian values

  void add_field(std::string name, ScalarType type);
  double value(const RawField& field, size_t index) const;
};

/// The attributes of `raw` as a PointCloud (see cloud_io.hpp for the field names read).
Result<PointCloud> to_point_cloud(const RawCloud& raw, bool drop_non_finite);
/// x, y, z and the attributes `cloud` has, as float32/uint16 fields.
RawCloud to_raw_cloud(const PointCloud& cloud);

/// PCD v0.5-0.7 (ascii, binary, binary_compressed) and PLY 1.0 (ascii, binary little/big
/// endian; the vertex element) parsers and writers. Parsers check every size against the file
/// before reading, so truncated or lying headers fail with a message instead of reading past
/// the data.
Result<RawCloud> parse_pcd(const std::string& bytes);
Result<RawCloud> parse_ply(const std::string& bytes);
std::string format_pcd(const RawCloud& raw);  // DATA binary
std::string format_ply(const RawCloud& raw);  // binary_little_endian

}  // namespace hanzo::fusion::cloud
