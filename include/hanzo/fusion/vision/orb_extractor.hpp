#pragma once
// OrbExtractor: ORB features (Rublee et al., ICCV 2011) spread over the whole image, the
// detector a visual frontend needs: a plain ORB keeps the strongest corners of the image, which
// crowd into the most textured region and leave the rest of the view without constraints.
//
// Per pyramid level l (image scaled by 1 / scale_factor^l, budget shrinking geometrically with
// the level as in ORB-SLAM):
//   1. FAST-9 corners with non-maximum suppression at min_fast_threshold;
//   2. grid bucketing: the level is cut into cells of cell_size pixels; a cell keeps its corners
//      at or above initial_fast_threshold, or, when it has none (low contrast: sky, shadow,
//      walls), its weaker corners down to min_fast_threshold (the adaptive threshold);
//   3. the budget is filled round-robin over the cells: every cell's best corner, then every
//      cell's second best, ..., so textured cells cannot take the budget from the others;
//   4. orientation by the intensity centroid of a 31-pixel disc (ORB, eq. 2-3).
// Descriptors are OpenCV's rotated BRIEF (256 bits, 32 bytes a row) computed for these keypoints.
//
// Keypoints are in level-0 pixel coordinates (u right, v down, origin at the centre of the
// top-left pixel), octave = pyramid level, size = 31 scale_factor^level, angle in degrees.
// Failure: an empty image, a type other than 8-bit grey / BGR / BGRA, an image smaller than
// 2 x 31 pixels, a mask of another size or type, or a configuration out of range.

#include <cstdint>
#include <cstring>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::vision {

struct OrbExtractorConfig {
  /// Keypoints kept over all levels (fewer where the image has fewer corners).
  int max_features = 1000;
  /// Scale between pyramid levels (> 1) and the number of levels (1..16).
  double scale_factor = 1.2;
  int pyramid_levels = 8;
  /// Grid cell side in pixels at every level (bucketing); 8..256. Smaller cells spread the
  /// keypoints more evenly but take weaker corners; 48 balances the two (docs/vision.md: 87 of
  /// the 96 cells of a 16 x 6 grid on a KITTI frame, OpenCV's ORB 51).
  int cell_size = 48;
  /// FAST thresholds (grey levels, 1..255): corners at initial_fast_threshold are preferred, a
  /// cell without any falls back to min_fast_threshold. initial >= min.
  int initial_fast_threshold = 20;
  int min_fast_threshold = 7;
  /// Sub-pixel keypoint positions (cv::cornerSubPix over 5 x 5 pixels of the keypoint's level).
  bool subpixel = true;
};

/// Keypoints and their descriptors (row i describes keypoints[i]; CV_8UC1, 32 bytes a row).
struct ImageFeatures {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  cv::Size image_size;

  std::size_t size() const { return keypoints.size(); }
};

/// Checks every field of the configuration; the error names the first field out of range.
Status validate(const OrbExtractorConfig& config);

class OrbExtractor {
 public:
  /// The configuration is checked by extract() (validate()).
  explicit OrbExtractor(OrbExtractorConfig config = {});

  /// Features of an 8-bit grey, BGR or BGRA image. mask (optional): CV_8UC1 of the image's
  /// size; keypoints only where it is non-zero. Thread-safe (no state is changed).
  Result<ImageFeatures> extract(const cv::Mat& image, const cv::Mat& mask = cv::Mat()) const;

  const OrbExtractorConfig& config() const { return config_; }

 private:
  OrbExtractorConfig config_;
};

/// Hamming distance between two 32-byte ORB descriptors (rows of ImageFeatures::descriptors).
/// Inline: the innermost operation of every matcher (the vision module is built with the CPU's
/// popcount instruction where the architecture has one).
inline int hamming_distance(const unsigned char* descriptor_a, const unsigned char* descriptor_b) {
  int distance = 0;
  for (int word = 0; word < 4; ++word) {
    std::uint64_t a = 0, b = 0;
    std::memcpy(&a, descriptor_a + 8 * word, 8);
    std::memcpy(&b, descriptor_b + 8 * word, 8);
    distance += __builtin_popcountll(a ^ b);
  }
  return distance;
}

}  // namespace hanzo::fusion::vision
