#pragma once
// Point-cloud files: PCD (PCL's format, v0.5-0.7, ascii/binary/binary_compressed), PLY (ascii,
// binary little/big endian) and KITTI Velodyne .bin (float32 x, y, z, reflectance per point).
// The format follows the file extension (.pcd, .ply, .bin; case-insensitive). The parsers are
// our own, checked against PCL's reader and writer in the tests: PCL 1.13's readers crash on
// some malformed files (a text file named .pcd, a PLY header announcing 4e9 vertices), and a
// bad file must give an error, never take the process down.
//
// Fields read besides x, y, z: intensity ("intensity", "scalar_intensity", "reflectance"),
// ring ("ring"), per-point time: "time" (s, Velodyne), "t" and "offset_time" (integer ns,
// Ouster and Livox), "timestamp" (absolute s, Hesai; made relative to the earliest point).
// Any numeric field type is accepted. Written files hold x, y, z and those attributes the cloud
// has (intensity, ring, time in s), plus normal_x/y/z when the cloud has normals.

#include <string>
#include <string_view>

#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::cloud {

/// Reads a PCD, PLY or KITTI .bin file. Fails, naming the path, on a missing or malformed file,
/// a file without x/y/z, non-finite coordinates (unless drop_non_finite: organized clouds mark
/// missing returns with NaN; how many were dropped is logged as a warning), a non-finite
/// intensity, time or normal (naming the point's index in the file) or an unknown extension.
Result<PointCloud> read_cloud(const std::string& path, bool drop_non_finite = true);

/// Writes `cloud` as PCD or PLY (binary) or KITTI .bin, atomically (a temporary file renamed
/// into place). Fails on an unknown extension, an invalid cloud or an unwritable path.
Status write_cloud(const std::string& path, const PointCloud& cloud);

/// The bytes write_cloud writes, for `format` "pcd", "ply" or "bin" (a server response).
/// Fails on an unknown format or an invalid cloud.
Result<std::string> encode_cloud(const PointCloud& cloud, std::string_view format);

}  // namespace hanzo::fusion::cloud
