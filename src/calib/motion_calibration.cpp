#include "hanzo/fusion/calib/motion_calibration.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <fmt/format.h>

#include "hanzo/fusion/core/so3.hpp"

namespace hanzo::fusion::calib {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

// The body's motion as a function of body time (seconds since the reference time): from
// poses (interpolated: slerp and linear) or from the gyroscope (integrated with the midpoint
// rule, the bias subtracted).
class BodyMotion {
 public:
  BodyMotion(const std::vector<StampedPose>& poses, const std::vector<GyroSample>& gyro, Timestamp reference)
      : poses_(&poses), gyro_(&gyro) {
    const std::size_t count = poses.empty() ? gyro.size() : poses.size();
    times_.reserve(count);
    for (std::size_t i = 0; i < count; ++i) {
      const Timestamp time = poses.empty() ? gyro[i].time : poses[i].time;
      times_.push_back((time - reference).seconds());
    }
    if (poses.empty()) set_gyro_bias(Eigen::Vector3d::Zero());
  }

  bool from_gyro() const { return poses_->empty(); }
  double start() const { return times_.front(); }
  double end() const { return times_.back(); }

  // Re-integrates the gyroscope with `bias` subtracted.
  void set_gyro_bias(const Eigen::Vector3d& bias) {
    bias_ = bias;
    orientations_.assign(times_.size(), SO3::identity());
    for (std::size_t k = 0; k + 1 < times_.size(); ++k) {
      orientations_[k + 1] = orientations_[k] * SO3::exp(rate(k) * (times_[k + 1] - times_[k]));
    }
  }

  // The body's motion from time a to time b (T_body(a)^-1 T_body(b)); rotation only from the gyroscope.
  SE3 relative(double a, double b) const {
    if (from_gyro()) return SE3(rotation_at(a).inverse() * rotation_at(b), Eigen::Vector3d::Zero());
    return pose_at(a).inverse() * pose_at(b);
  }

 private:
  std::size_t interval(double time) const {
    const auto upper = std::upper_bound(times_.begin(), times_.end(), time);
    const std::size_t index = upper == times_.begin() ? 0 : static_cast<std::size_t>(upper - times_.begin()) - 1;
    return std::min(index, times_.size() - 2);
  }
  Eigen::Vector3d rate(std::size_t k) const {
    return 0.5 * ((*gyro_)[k].angular_velocity + (*gyro_)[k + 1].angular_velocity) - bias_;
  }
  SO3 rotation_at(double time) const {
    const std::size_t k = interval(time);
    return orientations_[k] * SO3::exp(rate(k) * (time - times_[k]));
  }
  SE3 pose_at(double time) const {
    const std::size_t k = interval(time);
    const double fraction = (time - times_[k]) / (times_[k + 1] - times_[k]);
    const SE3& a = (*poses_)[k].pose;
    const SE3& b = (*poses_)[k + 1].pose;
    return SE3(SO3::interpolate(a.rotation(), b.rotation(), fraction),
               a.translation() + fraction * (b.translation() - a.translation()));
  }

  const std::vector<StampedPose>* poses_;
  const std::vector<GyroSample>* gyro_;
  std::vector<double> times_;
  std::vector<SO3> orientations_;
  Eigen::Vector3d bias_ = Eigen::Vector3d::Zero();
};

// One relative motion of the sensor, [start, end] in sensor time (seconds since the reference).
struct Pair {
  double start = 0.0;
  double end = 0.0;
  SE3 sensor_motion;                 // B
  Eigen::Vector3d sensor_rotation;   // log R_B
  bool turns = false;                // |log R_B| >= min_pair_rotation
  bool outlier = false;
};

template <typename Sample, typename Value>
Status check_series(const std::vector<Sample>& samples, const char* name, Value value) {
  for (std::size_t i = 0; i < samples.size(); ++i) {
    if (!value(samples[i]).allFinite()) return Error(fmt::format("{}[{}]: non-finite value", name, i), fmt::format("{}[{}]", name, i));
    if (i > 0 && samples[i].time <= samples[i - 1].time) {
      return Error(fmt::format("{}[{}]: timestamp {} s does not increase (previous {} s)", name, i,
                               samples[i].time.seconds(), samples[i - 1].time.seconds()),
                   fmt::format("{}[{}]", name, i));
    }
  }
  return {};
}

Status check_input(const MotionCalibrationInput& input, const MotionCalibrationConfig& config) {
  if (input.sensor.empty()) return Error("sensor: the sensor's name is empty", "sensor");
  if (!(config.pair_interval > 0.0) || !std::isfinite(config.pair_interval)) return Error("pair_interval: must be positive", "pair_interval");
  if (!(config.min_pair_rotation >= 0.0) || config.min_pair_rotation >= M_PI) return Error("min_pair_rotation: must be in [0, pi)", "min_pair_rotation");
  if (config.min_pairs < 3) return Error("min_pairs: at least 3 pairs are needed for a rotation", "min_pairs");
  if (config.estimate_time_offset && (!(config.max_time_offset > 0.0) || !std::isfinite(config.max_time_offset))) {
    return Error("max_time_offset: must be positive", "max_time_offset");
  }
  if (config.estimate_time_offset && (!(config.time_offset_step > 0.0) || config.time_offset_step > config.max_time_offset)) {
    return Error("time_offset_step: must be positive and at most max_time_offset", "time_offset_step");
  }
  if (!(config.outlier_factor > 1.0)) return Error("outlier_factor: must be above 1", "outlier_factor");
  if (!config.prior_translation.allFinite()) return Error("prior_translation: non-finite value", "prior_translation");
  if (input.body_poses.empty() == input.body_gyro.empty()) {
    return Error("give the body's motion as body poses or as gyroscope samples (exactly one of them)", "body_poses");
  }
  if (input.sensor_poses.size() < 2) return Error(fmt::format("sensor_poses: {} poses, at least 2 needed", input.sensor_poses.size()), "sensor_poses");
  const std::size_t body_count = std::max(input.body_poses.size(), input.body_gyro.size());
  const char* body_name = input.body_poses.empty() ? "gyro" : "body_poses";
  if (body_count < 2) return Error(fmt::format("{}: 1 sample, at least 2 needed", body_name), body_name);
  const auto pose_values = [](const StampedPose& sample) {
    Eigen::Matrix<double, 7, 1> values;
    values << sample.pose.translation(), sample.pose.rotation().quaternion().coeffs();
    return values;
  };
  HANZO_RETURN_IF_ERROR(check_series(input.sensor_poses, "sensor_poses", pose_values));
  HANZO_RETURN_IF_ERROR(check_series(input.body_poses, "body_poses", pose_values));
  HANZO_RETURN_IF_ERROR(check_series(input.body_gyro, "gyro", [](const GyroSample& sample) { return sample.angular_velocity; }));
  return {};
}

// R maximizing sum a_k^T R b_k (Kabsch / Park & Martin) and the singular-value spread of sum b a^T.
std::pair<SO3, double> align_rotation_axes(const std::vector<Eigen::Vector3d>& body_rotations,
                                           const std::vector<Eigen::Vector3d>& sensor_rotations) {
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (std::size_t k = 0; k < body_rotations.size(); ++k) covariance += sensor_rotations[k] * body_rotations[k].transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d sign = Eigen::Matrix3d::Identity();
  sign(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  const Eigen::Matrix3d rotation = svd.matrixV() * sign * svd.matrixU().transpose();
  const Eigen::Vector3d singular = svd.singularValues();
  return {SO3::from_matrix(rotation), singular(0) > 0.0 ? std::sqrt(singular(1) / singular(0)) : 0.0};
}

class Solver {
 public:
  Solver(const MotionCalibrationInput& input, const MotionCalibrationConfig& config)
      : input_(input), config_(config), reference_(input.sensor_poses.front().time),
        body_(input.body_poses, input.body_gyro, reference_) {}

  Result<MotionCalibrationSummary> run() {
    HANZO_RETURN_IF_ERROR(form_pairs());
    offset_ = config_.initial_time_offset.seconds();
    if (config_.estimate_time_offset) offset_ = scan_time_offset();
    HANZO_RETURN_IF_ERROR(solve_rotation());
    reject_outliers();
    HANZO_RETURN_IF_ERROR(solve_rotation());
    if (config_.estimate_time_offset) {
      refine_time_offset();
      HANZO_RETURN_IF_ERROR(solve_rotation());
    }
    MotionCalibrationSummary summary;
    summary.calibration.sensor = input_.sensor;
    summary.calibration.rotation_wxyz = rotation_.wxyz();
    summary.calibration.translation = config_.prior_translation;
    summary.calibration.time_offset = Duration::from_seconds(offset_);
    summary.gyro_bias = gyro_bias_;
    summary.pairs = pairs_.size();
    for (const Pair& pair : pairs_) {
      summary.rotation_pairs += pair.turns && !pair.outlier ? 1 : 0;
      summary.outlier_pairs += pair.outlier ? 1 : 0;
    }
    summary.rotation_residual_rms_deg = std::sqrt(rotation_cost(offset_) / static_cast<double>(summary.rotation_pairs)) * kRadToDeg;
    summary.rotation_axis_spread = axis_spread_;
    if (!body_.from_gyro()) solve_translation(summary);
    return summary;
  }

 private:
  Status form_pairs() {
    const double margin = config_.estimate_time_offset ? config_.max_time_offset : 0.0;
    const double centre = config_.initial_time_offset.seconds();
    const std::vector<StampedPose>& poses = input_.sensor_poses;
    std::size_t turning = 0;
    for (std::size_t i = 0, j = 1; j < poses.size(); ++j) {
      const double start = (poses[i].time - reference_).seconds();
      const double end = (poses[j].time - reference_).seconds();
      if (end - start < config_.pair_interval) continue;
      if (start + centre - margin >= body_.start() && end + centre + margin <= body_.end() &&
          end - start <= 3.0 * config_.pair_interval) {  // longer: a gap in the sensor's poses
        Pair pair;
        pair.start = start;
        pair.end = end;
        pair.sensor_motion = poses[i].pose.inverse() * poses[j].pose;
        pair.sensor_rotation = pair.sensor_motion.rotation().log();
        pair.turns = pair.sensor_rotation.norm() >= config_.min_pair_rotation;
        turning += pair.turns ? 1 : 0;
        pairs_.push_back(std::move(pair));
      }
      i = j;
    }
    if (pairs_.size() < config_.min_pairs) {
      return Error(fmt::format("only {} sensor motions of {} s overlap the body's {} (with a {} s offset margin), {} needed: "
                               "the two time ranges must overlap",
                               pairs_.size(), config_.pair_interval, body_.from_gyro() ? "gyroscope" : "poses", margin,
                               config_.min_pairs));
    }
    if (turning < config_.min_pairs) {
      return Error(fmt::format("only {} of {} sensor motions turn by at least {} rad, {} needed: the motion must rotate",
                               turning, pairs_.size(), config_.min_pair_rotation, config_.min_pairs));
    }
    return {};
  }

  SE3 body_motion(const Pair& pair, double offset) const { return body_.relative(pair.start + offset, pair.end + offset); }

  // Step 2: rotation angles of body and sensor agree at the right offset, whatever R_X is.
  double angle_cost(double offset) const {
    double cost = 0.0;
    for (const Pair& pair : pairs_) {
      const double difference = body_motion(pair, offset).rotation().angle() - pair.sensor_rotation.norm();
      cost += difference * difference;
    }
    return cost;
  }

  double scan_time_offset() const {
    const double centre = config_.initial_time_offset.seconds();
    const int steps = static_cast<int>(std::floor(config_.max_time_offset / config_.time_offset_step));
    double best_offset = centre;
    double best_cost = std::numeric_limits<double>::infinity();
    for (int step = -steps; step <= steps; ++step) {
      const double offset = centre + step * config_.time_offset_step;
      const double cost = angle_cost(offset);
      if (cost < best_cost) {
        best_cost = cost;
        best_offset = offset;
      }
    }
    return best_offset;
  }

  // The rotation residual of one pair: log((R_X R_B R_X^-1)^-1 R_A).
  Eigen::Vector3d rotation_residual(const Pair& pair, double offset) const {
    const SO3 predicted = rotation_ * pair.sensor_motion.rotation() * rotation_.inverse();
    return (predicted.inverse() * body_motion(pair, offset).rotation()).log();
  }

  double rotation_cost(double offset) const {
    double cost = 0.0;
    for (const Pair& pair : pairs_) {
      if (pair.turns && !pair.outlier) cost += rotation_residual(pair, offset).squaredNorm();
    }
    return cost;
  }

  // Step 3: R_X (and the gyroscope bias) at the current offset.
  Status solve_rotation() {
    const bool with_bias = body_.from_gyro() && config_.estimate_gyro_bias;
    for (int round = 0; round < (with_bias ? 8 : 1); ++round) {
      std::vector<Eigen::Vector3d> body_rotations;
      std::vector<Eigen::Vector3d> sensor_rotations;
      for (const Pair& pair : pairs_) {
        if (!pair.turns || pair.outlier) continue;
        body_rotations.push_back(body_motion(pair, offset_).rotation().log());
        sensor_rotations.push_back(pair.sensor_rotation);
      }
      std::tie(rotation_, axis_spread_) = align_rotation_axes(body_rotations, sensor_rotations);
      if (axis_spread_ < config_.min_rotation_axis_spread) {
        return Error(fmt::format("the motion turned about one axis only (axis spread {:.3g} < {}): the rotation about it is "
                                 "unobservable; turn about a second axis",
                                 axis_spread_, config_.min_rotation_axis_spread));
      }
      if (!with_bias) break;
      // The residual of a pair is about (true bias - estimated bias) x its duration.
      Eigen::Vector3d weighted = Eigen::Vector3d::Zero();
      double weight = 0.0;
      for (const Pair& pair : pairs_) {
        if (pair.outlier) continue;
        const double duration = pair.end - pair.start;
        weighted += rotation_residual(pair, offset_) * duration;
        weight += duration * duration;
      }
      const Eigen::Vector3d step = weighted / weight;
      gyro_bias_ += step;
      body_.set_gyro_bias(gyro_bias_);
      if (step.norm() < 1e-7) break;
    }
    return {};
  }

  void reject_outliers() {
    std::vector<double> residuals;
    for (const Pair& pair : pairs_) {
      if (pair.turns) residuals.push_back(rotation_residual(pair, offset_).norm());
    }
    std::vector<double> sorted = residuals;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
    const double threshold = std::max(config_.outlier_factor * sorted[sorted.size() / 2], 0.1 / kRadToDeg);
    std::size_t kept = 0;
    std::size_t index = 0;
    for (Pair& pair : pairs_) {
      if (!pair.turns) continue;
      pair.outlier = residuals[index++] > threshold;
      kept += pair.outlier ? 0 : 1;
    }
    if (kept < config_.min_pairs) {  // too few left: keep every pair rather than fail on noise
      for (Pair& pair : pairs_) pair.outlier = false;
    }
  }

  // Golden-section search of the full rotation residual around the scanned offset.
  void refine_time_offset() {
    const double golden = (std::sqrt(5.0) - 1.0) / 2.0;
    double low = offset_ - 2.0 * config_.time_offset_step;
    double high = offset_ + 2.0 * config_.time_offset_step;
    double left = high - golden * (high - low);
    double right = low + golden * (high - low);
    double cost_left = rotation_cost(left);
    double cost_right = rotation_cost(right);
    while (high - low > 1e-6) {
      if (cost_left < cost_right) {
        high = right;
        right = left;
        cost_right = cost_left;
        left = high - golden * (high - low);
        cost_left = rotation_cost(left);
      } else {
        low = left;
        left = right;
        cost_left = cost_right;
        right = low + golden * (high - low);
        cost_right = rotation_cost(right);
      }
    }
    offset_ = 0.5 * (low + high);
  }

  // Step 4: (R_A - I) t_X = R_X t_B - t_A, least squares; unobservable directions from the prior.
  void solve_translation(MotionCalibrationSummary& summary) const {
    Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
    Eigen::Vector3d right_side = Eigen::Vector3d::Zero();
    std::vector<std::pair<Eigen::Matrix3d, Eigen::Vector3d>> rows;
    for (const Pair& pair : pairs_) {
      if (pair.outlier) continue;
      const SE3 body = body_motion(pair, offset_);
      const Eigen::Matrix3d coefficients = body.rotation().matrix() - Eigen::Matrix3d::Identity();
      const Eigen::Vector3d value = rotation_ * pair.sensor_motion.translation() - body.translation();
      normal += coefficients.transpose() * coefficients;
      right_side += coefficients.transpose() * value;
      rows.emplace_back(coefficients, value);
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(normal);  // ascending eigenvalues
    const Eigen::Vector3d values = eigen.eigenvalues().cwiseMax(0.0);
    const Eigen::Matrix3d vectors = eigen.eigenvectors();
    const double largest = values(2);
    summary.translation_observability = largest > 0.0 ? std::sqrt(values(0) / largest) : 0.0;
    // t = prior + sum over observable directions v of (v^T (b - N prior) / lambda) v.
    const Eigen::Vector3d prior = config_.prior_translation;
    const Eigen::Vector3d residual_side = right_side - normal * prior;
    Eigen::Vector3d translation = prior;
    for (int i = 0; i < 3; ++i) {
      const bool observable = largest > 0.0 && std::sqrt(values(i) / largest) >= config_.min_translation_observability;
      if (observable) {
        translation += vectors.col(i) * (vectors.col(i).dot(residual_side) / values(i));
      } else if (!summary.unobservable_translation_axis) {
        summary.unobservable_translation_axis = vectors.col(i);
      }
    }
    double squared = 0.0;
    for (const auto& [coefficients, value] : rows) squared += (coefficients * translation - value).squaredNorm();
    summary.translation_residual_rms_m = std::sqrt(squared / static_cast<double>(rows.size()));
    summary.calibration.translation = translation;
    summary.translation_estimated = true;
  }

  const MotionCalibrationInput& input_;
  const MotionCalibrationConfig& config_;
  Timestamp reference_;
  BodyMotion body_;
  std::vector<Pair> pairs_;
  double offset_ = 0.0;
  SO3 rotation_;
  double axis_spread_ = 0.0;
  Eigen::Vector3d gyro_bias_ = Eigen::Vector3d::Zero();
};

}  // namespace

Result<MotionCalibrationSummary> calibrate_from_motion(const MotionCalibrationInput& input, const MotionCalibrationConfig& config) {
  HANZO_RETURN_IF_ERROR(check_input(input, config));
  return Solver(input, config).run();
}

}  // namespace hanzo::fusion::calib
