// Camera projection: PinholeCamera against OpenCV's projectPoints (radtan) and
// fisheye::projectPoints (equidistant), its Jacobian and the factors' Jacobians against
// numerical differentiation, landmarks behind the camera refused, and a small bundle
// adjustment recovering a pose and the landmarks from noisy pixels.

#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/projection_factors.hpp"

namespace hanzo::fusion::graph {
namespace {

using ::testing::HasSubstr;

PinholeCamera camera_with(PinholeCamera::Distortion distortion) {
  PinholeCamera camera;
  camera.fx = 458.654;
  camera.fy = 457.296;
  camera.cx = 367.215;
  camera.cy = 248.375;
  camera.distortion = distortion;
  if (distortion == PinholeCamera::Distortion::kRadtan) camera.coefficients = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.01};
  if (distortion == PinholeCamera::Distortion::kEquidistant) camera.coefficients = {-0.013, 0.021, -0.012, 0.003, 0.0};
  return camera;
}

TEST(PinholeCamera, MatchesOpenCvAndItsJacobian) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> lateral(-1.5, 1.5), depth(1.0, 8.0);
  const cv::Matx33d K(458.654, 0.0, 367.215, 0.0, 457.296, 248.375, 0.0, 0.0, 1.0);
  for (auto distortion : {PinholeCamera::Distortion::kNone, PinholeCamera::Distortion::kRadtan, PinholeCamera::Distortion::kEquidistant}) {
    const PinholeCamera camera = camera_with(distortion);
    std::vector<cv::Point3d> points;
    for (int i = 0; i < 50; ++i) points.emplace_back(lateral(rng), lateral(rng), depth(rng));
    std::vector<cv::Point2d> expected;
    if (distortion == PinholeCamera::Distortion::kEquidistant) {
      cv::fisheye::projectPoints(points, expected, cv::Vec3d::zeros(), cv::Vec3d::zeros(), K,
                                 cv::Vec4d(camera.coefficients[0], camera.coefficients[1], camera.coefficients[2], camera.coefficients[3]));
    } else {
      const std::vector<double> coefficients(camera.coefficients.begin(), camera.coefficients.end());
      cv::projectPoints(points, cv::Vec3d::zeros(), cv::Vec3d::zeros(), K,
                        distortion == PinholeCamera::Distortion::kRadtan ? coefficients : std::vector<double>{}, expected);
    }
    for (size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3d p(points[i].x, points[i].y, points[i].z);
      Eigen::Matrix<double, 2, 3> jacobian;
      const Eigen::Vector2d pixel = camera.project(p, &jacobian).value();
      EXPECT_LT((pixel - Eigen::Vector2d(expected[i].x, expected[i].y)).norm(), 1e-6) << i;
      for (int k = 0; k < 3; ++k) {
        Eigen::Vector3d step = Eigen::Vector3d::Zero();
        step(k) = 1e-6;
        const Eigen::Vector2d numeric = (camera.project(p + step).value() - camera.project(p - step).value()) / 2e-6;
        EXPECT_LT((jacobian.col(k) - numeric).norm(), 1e-4 * (1.0 + numeric.norm())) << i << " " << k;
      }
    }
  }
  EXPECT_FALSE(camera_with(PinholeCamera::Distortion::kNone).project({0.0, 0.0, -1.0}));
}

// unproject() inverts project() over the image (EuRoC's 752 x 480 camera) for every model, and
// agrees with OpenCV's undistortPoints / fisheye::undistortPoints.
TEST(PinholeCamera, UnprojectInvertsProjectAndMatchesOpenCv) {
  const cv::Matx33d K(458.654, 0.0, 367.215, 0.0, 457.296, 248.375, 0.0, 0.0, 1.0);
  for (auto distortion : {PinholeCamera::Distortion::kNone, PinholeCamera::Distortion::kRadtan, PinholeCamera::Distortion::kEquidistant}) {
    const PinholeCamera camera = camera_with(distortion);
    for (double u = 0.0; u <= 752.0; u += 47.0) {
      for (double v = 0.0; v <= 480.0; v += 40.0) {
        const std::optional<Eigen::Vector2d> normalized = camera.unproject({u, v});
        ASSERT_TRUE(normalized) << u << " " << v;
        const Eigen::Vector2d pixel = camera.project(normalized->homogeneous()).value();
        EXPECT_LT((pixel - Eigen::Vector2d(u, v)).norm(), 1e-6) << u << " " << v;
        std::vector<cv::Point2d> in{{u, v}}, out;
        if (distortion == PinholeCamera::Distortion::kEquidistant) {
          cv::fisheye::undistortPoints(in, out, K, cv::Vec4d(camera.coefficients[0], camera.coefficients[1], camera.coefficients[2], camera.coefficients[3]));
        } else if (distortion == PinholeCamera::Distortion::kRadtan) {
          cv::undistortPoints(in, out, K, std::vector<double>(camera.coefficients.begin(), camera.coefficients.end()), cv::noArray(), cv::noArray(),
                              cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12));
        } else {
          out = {{(u - K(0, 2)) / K(0, 0), (v - K(1, 2)) / K(1, 1)}};
        }
        EXPECT_LT((*normalized - Eigen::Vector2d(out[0].x, out[0].y)).norm(), 1e-5) << u << " " << v;
      }
    }
  }
}

// Central differences in the pose's tangent space and the point's coordinates.
void expect_jacobians_match(const Factor& factor, const Values& values) {
  std::vector<Eigen::MatrixXd> analytic;
  ASSERT_TRUE(factor.evaluate(values, &analytic).ok());
  constexpr double h = 1e-6;
  for (int k = 0; k < 6; ++k) {
    SE3::Tangent delta = SE3::Tangent::Zero();
    delta(k) = h;
    Values plus = values, minus = values;
    plus.insert(factor.keys()[0], values.at<SE3>(factor.keys()[0]).value() * SE3::exp(delta));
    minus.insert(factor.keys()[0], values.at<SE3>(factor.keys()[0]).value() * SE3::exp(-delta));
    const Eigen::VectorXd numeric = (factor.evaluate(plus, nullptr).value() - factor.evaluate(minus, nullptr).value()) / (2 * h);
    EXPECT_LT((analytic[0].col(k) - numeric).cwiseAbs().maxCoeff(), 1e-5 * (1.0 + numeric.cwiseAbs().maxCoeff())) << "pose " << k;
  }
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d step = Eigen::Vector3d::Zero();
    step(k) = h;
    Values plus = values, minus = values;
    plus.insert(factor.keys()[1], Eigen::Vector3d(values.at<Eigen::Vector3d>(factor.keys()[1]).value() + step));
    minus.insert(factor.keys()[1], Eigen::Vector3d(values.at<Eigen::Vector3d>(factor.keys()[1]).value() - step));
    const Eigen::VectorXd numeric = (factor.evaluate(plus, nullptr).value() - factor.evaluate(minus, nullptr).value()) / (2 * h);
    EXPECT_LT((analytic[1].col(k) - numeric).cwiseAbs().maxCoeff(), 1e-5 * (1.0 + numeric.cwiseAbs().maxCoeff())) << "point " << k;
  }
}

// A forward-looking camera on a body (x forward, z up): camera z = body x.
const SE3 kBodyCamera(SO3::from_matrix((Eigen::Matrix3d() << 0, 0, 1, -1, 0, 0, 0, -1, 0).finished()), Eigen::Vector3d(0.2, 0.0, 0.5));

TEST(ProjectionFactors, JacobiansMatchNumericalDifferentiation) {
  const GaussianNoise noise2 = GaussianNoise::from_sigmas(Eigen::Vector2d(0.7, 0.5)).value();
  const GaussianNoise noise3 = GaussianNoise::from_sigmas(Eigen::Vector3d(0.7, 0.7, 0.5)).value();
  Values values;
  values.insert(X(0), SE3(SO3::exp({0.05, -0.03, 0.4}), Eigen::Vector3d(1.0, 2.0, 0.3)));
  values.insert(L(0), Eigen::Vector3d(6.0, 4.5, 1.2));
  for (auto distortion : {PinholeCamera::Distortion::kNone, PinholeCamera::Distortion::kRadtan, PinholeCamera::Distortion::kEquidistant}) {
    expect_jacobians_match(ProjectionFactor(X(0), L(0), {300.0, 200.0}, camera_with(distortion), kBodyCamera, noise2), values);
  }
  expect_jacobians_match(
      StereoProjectionFactor(X(0), L(0), {300.0, 280.0, 200.0}, camera_with(PinholeCamera::Distortion::kNone), 0.11, kBodyCamera, noise3),
      values);
  Values behind = values;
  behind.insert(L(0), Eigen::Vector3d(-6.0, -4.5, 1.2));
  EXPECT_THAT(ProjectionFactor(X(0), L(0), {300.0, 200.0}, camera_with(PinholeCamera::Distortion::kNone), kBodyCamera, noise2)
                  .evaluate(behind, nullptr)
                  .error()
                  .message,
              HasSubstr("l0 is behind the camera of x0"));
  EXPECT_FALSE(StereoProjectionFactor(X(0), L(0), {300.0, 280.0, 200.0}, camera_with(PinholeCamera::Distortion::kRadtan), 0.11, kBodyCamera,
                                      noise3)
                   .evaluate(values, nullptr)
                   .ok());
  EXPECT_THAT(ProjectionFactor(X(0), L(0), {300.0, 200.0}, camera_with(PinholeCamera::Distortion::kNone), kBodyCamera, noise3)
                  .evaluate(values, nullptr)
                  .error()
                  .message,
              HasSubstr("projection of l0: the noise is 3x3, not 2x2"));
}

// A stereo bundle adjustment (the optimizer evaluates projections through its own fixed-size
// path): its chi2 at the start is the factors' own, and it recovers a pose 0.3 m / 3 deg off and
// landmarks 0.5 m off from two known poses.
TEST(ProjectionFactors, StereoBundleAdjustmentRecoversPoseAndLandmarks) {
  std::mt19937 rng(9);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> ahead(4.0, 10.0), side(-4.0, 4.0), height(-1.0, 3.0);
  const PinholeCamera camera = camera_with(PinholeCamera::Distortion::kNone);
  const double baseline = 0.11;
  const std::vector<SE3> poses = {SE3(SO3(), {0.0, 0.0, 0.0}), SE3(SO3::exp({0.0, 0.0, 0.05}), {0.2, -0.5, 0.0}),
                                  SE3(SO3::exp({0.0, 0.02, 0.1}), {0.4, -1.0, 0.05})};
  const GaussianNoise pixel_noise = GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(0.5)).value();
  FactorGraph graph;
  Values values;
  std::vector<Eigen::Vector3d> landmarks;
  for (int j = 0; j < 30; ++j) {
    landmarks.emplace_back(ahead(rng), side(rng), height(rng));
    values.insert(L(j), Eigen::Vector3d(landmarks.back() + 0.5 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng))));
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d p = kBodyCamera.inverse() * (poses[i].inverse() * landmarks.back());
      const Eigen::Vector3d pixel(camera.fx * p.x() / p.z() + camera.cx, camera.fx * (p.x() - baseline) / p.z() + camera.cx,
                                  camera.fy * p.y() / p.z() + camera.cy);
      graph.emplace<StereoProjectionFactor>(X(i), L(j), pixel + 0.5 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng)), camera, baseline,
                                            kBodyCamera, pixel_noise);
    }
  }
  values.insert(X(0), poses[0]);
  values.insert(X(1), poses[1]);
  values.insert(X(2), SE3(poses[2].rotation() * SO3::exp({0.03, -0.03, 0.04}), poses[2].translation() + Eigen::Vector3d(0.2, -0.2, 0.1)));
  const double start_chi2 = graph.chi2(values).value();
  BatchOptimizerConfig config;
  config.fixed = {X(0), X(1)};
  const OptimizationSummary summary = optimize(graph, values, config).value();
  EXPECT_NEAR(summary.initial_chi2, start_chi2, 1e-9 * start_chi2);
  EXPECT_TRUE(summary.converged);
  EXPECT_LT(summary.final_chi2 / static_cast<double>(3 * graph.size()), 1.5);
  const SE3 error = poses[2].inverse() * values.at<SE3>(X(2)).value();
  EXPECT_LT(error.translation().norm(), 0.03);
  EXPECT_LT(error.rotation().angle(), 0.005);
  double squared = 0.0;
  for (int j = 0; j < 30; ++j) squared += (values.at<Eigen::Vector3d>(L(j)).value() - landmarks[j]).squaredNorm();
  EXPECT_LT(std::sqrt(squared / 30), 0.1);
}

// Three poses sliding sideways (the baseline across the view: good parallax), 40 landmarks
// 6-14 m ahead, pixels with 0.5 px noise through the radtan camera. The first two poses are known (they fix the gauge and the scale); the third starts
// 0.3 m / 3 deg off and the landmarks 0.5 m off: the bundle adjustment recovers them.
TEST(ProjectionFactors, BundleAdjustmentRecoversPoseAndLandmarks) {
  std::mt19937 rng(5);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> ahead(6.0, 14.0), side(-6.0, 6.0), height(-1.0, 4.0);
  const PinholeCamera camera = camera_with(PinholeCamera::Distortion::kRadtan);
  const std::vector<SE3> poses = {SE3(SO3(), {0.0, 0.0, 0.0}), SE3(SO3::exp({0.0, 0.0, 0.05}), {0.1, -1.0, 0.0}),
                                  SE3(SO3::exp({0.0, 0.02, 0.1}), {0.3, -2.0, 0.05})};
  const GaussianNoise pixel_noise = GaussianNoise::from_sigmas(Eigen::Vector2d::Constant(0.5)).value();
  FactorGraph graph;
  Values values;
  std::vector<Eigen::Vector3d> landmarks;
  for (int j = 0; j < 40; ++j) {
    landmarks.emplace_back(ahead(rng), side(rng), height(rng));
    values.insert(L(j), Eigen::Vector3d(landmarks.back() + 0.5 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng))));
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d p_camera = kBodyCamera.inverse() * (poses[i].inverse() * landmarks.back());
      const Eigen::Vector2d pixel = camera.project(p_camera).value() + 0.5 * Eigen::Vector2d(normal(rng), normal(rng));
      graph.emplace<ProjectionFactor>(X(i), L(j), pixel, camera, kBodyCamera, pixel_noise);
    }
  }
  values.insert(X(0), poses[0]);
  values.insert(X(1), poses[1]);
  values.insert(X(2), SE3(poses[2].rotation() * SO3::exp({0.03, -0.03, 0.04}), poses[2].translation() + Eigen::Vector3d(0.2, -0.2, 0.1)));
  BatchOptimizerConfig config;
  config.fixed = {X(0), X(1)};
  const OptimizationSummary summary = optimize(graph, values, config).value();
  EXPECT_TRUE(summary.converged);
  EXPECT_LT(summary.final_chi2 / static_cast<double>(2 * graph.size()), 1.5);  // residuals at the pixel noise
  const SE3 error = poses[2].inverse() * values.at<SE3>(X(2)).value();
  EXPECT_LT(error.translation().norm(), 0.05);   // started 0.3 m off
  EXPECT_LT(error.rotation().angle(), 0.005);    // started 0.058 rad off
  double squared = 0.0;
  for (int j = 0; j < 40; ++j) squared += (values.at<Eigen::Vector3d>(L(j)).value() - landmarks[j]).squaredNorm();
  std::printf("bundle adjustment: pose error %.4f m / %.5f rad, landmark RMSE %.3f m, %d iterations\n", error.translation().norm(),
              error.rotation().angle(), std::sqrt(squared / 40), summary.iterations);
  EXPECT_LT(std::sqrt(squared / 40), 0.2);  // started 0.87 m off; depth sigma at 10 m over a 1-2 m baseline: 0.05-0.11 m
}

}  // namespace
}  // namespace hanzo::fusion::graph
