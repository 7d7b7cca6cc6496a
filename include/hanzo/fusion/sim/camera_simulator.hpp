#pragma once
// CameraSimulator: global-shutter camera images rendered by ray casting the textured World.
//
// Frames: the camera frame is the optical frame (x right, y down, z forward) at T_body_camera
// on the body. Pixel (u, v) (OpenCV convention: integer coordinates are pixel centres) looks
// along the ray that the camera's distortion model maps onto it: the inverse of
// radtan (k1, k2, p1, p2[, k3]; OpenCV plumb_bob) or equidistant (k1..k4; OpenCV fisheye), so
// projecting a world point with the message's intrinsics and distortion (e.g. cv::projectPoints)
// lands where the renderer drew it.
//
// Shading: albedo * (ambient + diffuse * max(0, n . sun_direction) * lit), a vertical sky
// gradient where a ray hits nothing, all times exposure, Gaussian pixel noise (std in 8-bit grey
// levels), then quantized to mono8 (Rec. 709 luminance) or rgb8. The albedo is the texture's
// colour times tint, on upward surfaces (ground, roofs: normal z > 0.7) covered by snow in
// 0.4 m patches over snow_cover of their area; lit is 0 where a shadow ray towards the sun hits
// something within 100 m (shadows on), else 1. The same route rendered with another sun,
// exposure, shadows, tint or snow is the same place at another time of day or season. supersampling s renders s x s rays per pixel
// and averages them (anti-aliased edges for sub-pixel corner detection).
//
// Depth cameras (encoding depth16 / depth32f): the z-depth of the surface each pixel's centre
// sees, as a depth camera registered to a colour camera of the same intrinsics and mount gives.
//
// Faults inside an episode's [start, end]:
//   darkness      radiance * brightness (e.g. 0.05), pixel noise * noise_scale (gain noise)
//   glare         a saturating bloom: + strength * exp(-d^2 / (2 radius^2)) around `center`
//                 (pixels), as the sun in view does
//   motion_blur   the exposure lasts exposure_time seconds centred on the stamp: the image is
//                 the mean of blur_samples renders along the motion

#include <array>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"
#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::sim {

enum class CameraFaultType { kDarkness, kGlare, kMotionBlur };

/// Ground-truth detections of the moving boxes (people, vehicles) a camera sees: none, their
/// visible pixels' bounding boxes, or boxes with instance masks.
enum class GroundTruthDetections { kNone, kBoxes, kMasks };
std::string_view to_string(GroundTruthDetections detections);  // "none", "boxes", "masks"
std::optional<GroundTruthDetections> ground_truth_detections_from_string(std::string_view name);
std::string_view to_string(CameraFaultType type);  // "darkness", "glare", "motion_blur"
std::optional<CameraFaultType> camera_fault_type_from_string(std::string_view name);

struct CameraFaultEpisode {
  CameraFaultType type = CameraFaultType::kDarkness;
  Timestamp start;
  Timestamp end;
  double brightness = 0.05;                         ///< darkness: radiance gain, (0, 1]
  double noise_scale = 3.0;                         ///< darkness: pixel noise multiplier
  Eigen::Vector2d center{320.0, 120.0};             ///< glare: pixels
  double radius = 120.0;                            ///< glare: pixels
  double strength = 1.5;                            ///< glare: added radiance at the centre
  double exposure_time = 0.04;                      ///< motion blur: seconds
  int blur_samples = 6;                             ///< motion blur: renders averaged
};

struct CameraSimulatorConfig {
  double rate_hz = 20.0;
  msgs::CameraIntrinsics intrinsics{400.0, 400.0, 319.5, 239.5, 640, 480};
  msgs::DistortionModel distortion;  ///< none, radtan or equidistant
  /// mono8 or rgb8; depth16 (mm) or depth32f (m) for a depth camera: the z-depth of each pixel's
  /// centre ray (supersampling, lighting and faults do not apply), 0 (depth16) or NaN (depth32f)
  /// outside depth_range, with Gaussian noise of depth_noise x depth^2.
  msgs::ImageEncoding encoding = msgs::ImageEncoding::kMono8;
  Eigen::Vector2d depth_range{0.3, 10.0};  ///< m: the depth camera's measuring range
  double depth_noise = 0.0014;             ///< 1/m: standard deviation per depth^2 (a structured-light sensor's 1.4 mm at 1 m)
  SE3 T_body_camera;
  int supersampling = 1;                                ///< rays per pixel along each axis, 1..4
  double pixel_noise = 2.0;                             ///< grey levels (of 255), standard deviation
  Eigen::Vector3d sun_direction{0.3, 0.2, 0.93};        ///< world, towards the sun (normalized when used)
  double ambient = 0.45;
  double diffuse = 0.55;
  double exposure = 1.0;                                ///< radiance gain (> 0): dusk 0.3, the noise stays
  bool shadows = false;                                 ///< cast shadows (a second ray per pixel)
  Eigen::Vector3f tint{1.0F, 1.0F, 1.0F};               ///< per-channel albedo gain (>= 0): foliage, a season's colours
  double snow_cover = 0.0;                              ///< share of upward surfaces under snow, 0..1
  double max_distance = 200.0;                          ///< metres: farther surfaces are sky
  int num_threads = 1;                                  ///< rendering threads (TBB); 0: all cores
  std::vector<CameraFaultEpisode> faults;
  /// With kBoxes / kMasks, detections() gives each image's moving boxes as a perfect detector
  /// sees them: every moving box with at least min_detection_pixels visible pixels (pixel
  /// centres' rays that hit it first), its class, score 1, the box around those pixels, its
  /// index among the world's moving boxes as track id (and the pixels as its instance mask).
  GroundTruthDetections ground_truth_detections = GroundTruthDetections::kNone;
  int min_detection_pixels = 30;
  /// detections() also carries a dense segmentation: each pixel centre's first-hit object's
  /// class (the ground's, a box's, a cylinder's or a moving box's class_name; the sky
  /// unlabelled), the label table in the order ground, boxes, cylinders, moving boxes (each name
  /// once). segmentation_noise: the share of pixels given another class, drawn uniformly (a
  /// segmenter's errors, independent per pixel and frame).
  bool ground_truth_segmentation = false;
  double segmentation_noise = 0.0;
  std::string frame_id = "camera";
  uint64_t seed = 6;
};

class CameraSimulator {
 public:
  /// Fails on intrinsics without a size, an unsupported encoding, or distortion coefficients
  /// of the wrong count. world and trajectory must outlive the simulator.
  static Result<CameraSimulator> create(CameraSimulatorConfig config, const World& world, const SplineTrajectory& trajectory);

  /// The image exposed at `time`; call in increasing time order.
  msgs::ImageMessage measure(Timestamp time);
  /// The ground-truth detections (and segmentation) of the image measure() returned last
  /// (config ground_truth_detections, ground_truth_segmentation; nullopt when both are off, for
  /// a depth camera, or before any image).
  std::optional<msgs::DetectionsMessage> detections() const;
  /// The unit ray (camera frame) of image position (u, v) in pixels, after undistortion.
  Eigen::Vector3d pixel_ray(double u, double v) const;

 private:
  CameraSimulator(CameraSimulatorConfig config, const World& world, const SplineTrajectory& trajectory);
  /// Linear RGB radiance of every pixel (supersamples averaged) seen from the pose at time; with
  /// `depth`, instead the z-depth of each ray that hits (NaN for none; depth cameras cast one
  /// ray per pixel).
  /// object_ids (colour images): the object id (RayHit::object_id; -2 for the sky) each pixel
  /// centre's first sample sees.
  void render(Timestamp time, std::vector<Eigen::Vector3f>& radiance, std::vector<float>* depth = nullptr,
              std::vector<int>* object_ids = nullptr) const;
  msgs::ImageMessage measure_depth(Timestamp time);
  /// The last image's ground-truth segmentation into `message` (config ground_truth_segmentation).
  void add_segmentation(msgs::DetectionsMessage& message) const;
  /// The message without pixels: time, frame, size, encoding, intrinsics and distortion.
  msgs::ImageMessage image_header(Timestamp time) const;
  /// The next standard normal draw of the per-frame xorshift sequence `state`.
  float next_normal(uint64_t& state) const;

  CameraSimulatorConfig config_;
  const World* world_;
  const SplineTrajectory* trajectory_;
  static constexpr int kNormalTableBits = 16;
  static constexpr int kTilePixels = 16;  // image tiles of 16 x 16 pixels share one RayGroup
  /// The pyramid (camera frame, inward side normals through the centre, the last one the
  /// forward half space) enclosing the rays of one tile; none when a ray looks sideways or back.
  struct TilePyramid {
    bool valid = false;
    std::array<Eigen::Vector3d, 5> inward_normals;
  };
  std::vector<Eigen::Vector3f> rays_;  // unit, camera frame, (width * s) x (height * s), row-major
  std::vector<TilePyramid> tiles_;     // row-major, ceil(width / kTilePixels) per row
  std::vector<float> normal_table_;    // standard normal draws for pixel noise
  std::vector<int> object_ids_;        // the last image's (ground-truth detections)
  Timestamp object_ids_time_;
  std::vector<std::string> segmentation_classes_;  // the label table
  std::vector<uint8_t> class_of_object_;           // per object id + 1 (the ground first)
  Eigen::Vector3d sun_direction_;
  std::mt19937_64 random_;
};

}  // namespace hanzo::fusion::sim
