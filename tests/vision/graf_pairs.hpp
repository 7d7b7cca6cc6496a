#pragma once
// The graf image pair with its ground-truth homography, and a wide-baseline pair made from it:
// graf1 seen from 40 degrees further round (the plane-induced homography of a camera rotated
// about the picture's vertical axis through its centre), warped so that its true homography is
// known exactly.

#include <cmath>
#include <fstream>
#include <string>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::vision::testing {

struct GrafPair {
  cv::Mat image1, image2;
  cv::Matx33d homography;  ///< image-1 pixels to image-2 pixels
};

inline cv::Matx33d read_homography(const std::string& path) {
  std::ifstream file(path);
  cv::Matx33d homography;
  for (int i = 0; i < 9; ++i) file >> homography.val[i];
  return homography;
}

inline GrafPair graf_pair() {
  const std::string folder = std::string(HANZO_DATA_DIR) + "/feature_matching_graf/";
  return {cv::imread(folder + "graf1.png"), cv::imread(folder + "graf2.png"), read_homography(folder + "H_graf1_to_graf2_halfres.txt")};
}

/// The homography of a fronto-parallel plane at distance 1 seen by a camera of focal length f
/// (pixels) turned by `degrees` about the vertical axis through the plane's point at the image
/// centre: H = K R_y K^-1 for a rotation about the viewed point, i.e. K (R - t n^T) K^-1.
inline cv::Matx33d viewpoint_homography(cv::Size size, double focal, double degrees) {
  const double angle = degrees * CV_PI / 180.0, c = std::cos(angle), s = std::sin(angle);
  const cv::Matx33d K(focal, 0, size.width / 2.0, 0, focal, size.height / 2.0, 0, 0, 1);
  // Camera moved on a circle of radius 1 around the plane point (0, 0, 1), looking at it.
  const cv::Matx33d R(c, 0, s, 0, 1, 0, -s, 0, c);  // rows: the new camera's axes in the old frame
  const cv::Vec3d centre(std::sin(angle), 0, 1 - std::cos(angle));  // new camera centre in the old frame
  const cv::Vec3d t = -(R * centre);
  const cv::Matx31d normal(0, 0, 1);
  // Plane n^T X = 1 in the first camera: H = K (R + t n^T / d) K^-1 with d = 1.
  const cv::Matx33d H = K * (R + cv::Matx31d(t) * normal.t()) * K.inv();
  return H * (1.0 / H(2, 2));
}

inline GrafPair wide_baseline_pair(double degrees = 40.0) {
  GrafPair pair = graf_pair();
  const cv::Matx33d turn = viewpoint_homography(pair.image1.size(), 1.0 * pair.image1.cols, degrees);
  cv::Mat warped;
  cv::warpPerspective(pair.image1, warped, turn, pair.image1.size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  return {pair.image1, warped, turn};
}

}  // namespace hanzo::fusion::vision::testing
