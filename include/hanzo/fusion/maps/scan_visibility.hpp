#pragma once
// Free-space evidence from one LiDAR scan: did the scan see a map point, see through the place
// where it was, or learn nothing about it? The visibility test of range-image based moving
// point removal (Kim & Kim, "Remove, then Revert", IROS 2020: a map point is dynamic where a
// scan's range image measures farther than the point along its direction), made safe for
// surfaces seen at grazing angles by requiring rays on both sides of the point.
//
// The scan is stored as a spherical range image in its sensor frame: azimuth columns of
// azimuth_resolution_deg (wrapping around), elevation rows of elevation_resolution_deg over the
// scan's elevation span, each pixel the nearest return's range (m) falling in it. A point
// (sensor frame, range r) is compared with the returns nearest its direction: in its own and
// the two neighbouring columns, the pixel of its own row, the nearest filled pixel below that
// row and the nearest above it, each within bracket_deg of elevation (a return of its own row
// may lie a little above or below the point: it counts for neither side). With
// m = margin + margin_per_metre * r:
//   kSeen         some of them lies within m of r (the scan saw the point's surface);
//   kOccluded     else some lies nearer than r - m (the view was blocked before the point);
//   kSeenThrough  else, when rays both below and above the point were found and the surface
//                 they met lies farther than s = surface_margin + surface_margin_per_metre * r
//                 from the point: when the nearest hit below and the next hit below it lie on
//                 a floor (slope under 27 degrees), the point must float more than s above that
//                 hit (a floor point lifted by a pose error meets rays passing just under it far
//                 behind); otherwise its distance, in the vertical plane of its direction, to
//                 the line through the nearest hit below and the nearest above must exceed s.
//                 The space the point occupied was empty (Removert's "range image of the scan
//                 farther than the map's");
//   kUnknown      otherwise (no ray near its direction: outside the field of view, in the sky,
//                 past max_range, nearer than min_range, or between beams too far apart).
// Requiring a ray below and one above, and a surface behind farther than s, keeps a floor seen
// at a grazing angle. The lowest s of a moving object (the part nearest the ground) is never
// seen through.
//
// Frames and units: points in the scan's sensor frame, metres; angles in degrees in the config.
// Failure cases: a LiDAR whose beams lie more than bracket_deg apart gives kUnknown between
// its beams (no evidence, never wrong evidence); returns nearer than min_range (the vehicle
// itself) are left out of the image.

#include <cstddef>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::maps {

struct VisibilityConfig {
  double azimuth_resolution_deg = 0.5;    ///< range-image column width (deg, (0, 10])
  double elevation_resolution_deg = 0.25; ///< range-image row height (deg, (0, 10])
  double bracket_deg = 2.0;               ///< largest elevation gap (deg) to a ray below or above a point
  double min_range = 1.0;                 ///< m: nearer returns (the platform) and points are ignored
  double max_range = 80.0;                ///< m: farther points are kUnknown (their returns still count)
  double margin = 0.2;                   ///< m: a return within margin + margin_per_metre * range sees a point
  double margin_per_metre = 0.005;
  /// m: the surface behind a point seen through must lie farther than this (plus
  /// surface_margin_per_metre * range: the pose's angular error) from it.
  double surface_margin = 0.1;
  double surface_margin_per_metre = 0.003;

  /// Checks every field; the error names the first one out of range.
  Status validate() const;
};

enum class Visibility : unsigned char {
  kUnknown,
  kSeen,
  kSeenThrough,
  kOccluded,
};

class RangeImage {
 public:
  /// The range image of one scan (returns in the sensor frame), with the world's up direction
  /// (against gravity) in the sensor frame. The config must be valid.
  RangeImage(const VisibilityConfig& config, std::span<const Eigen::Vector3f> returns_in_sensor_frame,
             const Eigen::Vector3d& up_in_sensor_frame = Eigen::Vector3d::UnitZ());

  /// What the scan says about a point (in the same sensor frame).
  Visibility classify(const Eigen::Vector3f& point_in_sensor_frame) const;

  std::size_t memory_bytes() const { return pixels_.capacity() * sizeof(Pixel); }

 private:
  VisibilityConfig config_;
  Eigen::Vector3d up_ = Eigen::Vector3d::UnitZ();
  double azimuth_bins_per_radian_ = 0.0;
  double elevation_bins_per_radian_ = 0.0;
  double lowest_elevation_ = 0.0;  // rad, of row 0's lower edge
  int columns_ = 0;
  int rows_ = 0;
  int bracket_rows_ = 0;
  struct Pixel {
    Eigen::Vector3f point = Eigen::Vector3f::Zero();  // the return, sensor frame
    float range = 0.0F;      // m; 0: no return
    float elevation = 0.0F;  // rad, of that return
  };
  std::vector<Pixel> pixels_;  // columns_ x rows_, column-major
};

}  // namespace hanzo::fusion::maps
