// 3D Gaussian splats trained on the NeRF-synthetic lego (../shared/data/nerf_lego_400, real
// renders with exact poses) at a quarter of the resolution, scored on the held-out val views;
// transforms.json cameras against the file's numbers; bad transforms files refused by name.

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/neural/splat_trainer.hpp"
#include "hanzo/fusion/neural/view_dataset.hpp"
#include "hanzo/fusion/neural/view_points.hpp"

namespace hanzo::fusion::neural {
namespace {

const std::string kLego = std::string(HANZO_DATA_DIR) + "/nerf_lego_400";

/// The lego's `split` ("train", "val") at 1/downscale of its resolution.
Result<ViewDataset> lego(const std::string& split, int downscale) {
  ViewDatasetConfig config;
  config.downscale = downscale;
  return load_transforms(kLego + "/transforms_" + split + ".json", config);
}

TEST(ViewDataset, LegoCamerasFollowTheBlenderConvention) {
  ViewDatasetConfig config;
  config.load_images = false;
  const Result<ViewDataset> dataset = load_transforms(kLego + "/transforms_train.json", config);
  ASSERT_TRUE(dataset) << dataset.error().message;
  ASSERT_EQ(dataset->views.size(), 100u);
  const SplatCamera& camera = dataset->views[0].camera;
  EXPECT_EQ(camera.width, 400);
  EXPECT_NEAR(camera.fx, 0.5 * 400 / std::tan(0.5 * 0.6911112070083618), 1e-9);
  EXPECT_NEAR(camera.cx, 199.5, 1e-12);
  // r_0's camera centre is the matrix's last column; the origin (the model) is in front of it.
  EXPECT_NEAR(camera.centre_world().x(), -0.05379832163453102, 1e-5);  // the file's rotation is orthonormal to 1e-7
  EXPECT_NEAR(camera.centre_world().y(), 3.845470428466797, 1e-5);
  EXPECT_GT((camera.R_camera_world * Eigen::Vector3d::Zero() + camera.t_camera_world).z(), 3.0);
  // Every camera looks at the model: the point nearest their axes is near the origin.
  EXPECT_LT(dataset->scene_centre.norm(), 0.3);
  EXPECT_NEAR(dataset->camera_distance, 4.03, 0.1);
}

TEST(ViewDataset, BadTransformsFilesAreRefusedNamingTheField) {
  const std::filesystem::path folder = std::filesystem::temp_directory_path() / "hanzo_bad_transforms";
  std::filesystem::create_directories(folder);
  const auto refused = [&](const std::string& text) {
    std::ofstream(folder / "transforms.json") << text;
    const Result<ViewDataset> dataset = load_transforms((folder / "transforms.json").string());
    return dataset ? std::string("accepted") : dataset.error().message;
  };
  EXPECT_NE(refused("{").find("not JSON"), std::string::npos);
  EXPECT_NE(refused(R"({"camera_angle_x": 0.7})").find("no frames"), std::string::npos);
  EXPECT_NE(refused(R"({"camera_angle_x": "wide", "frames": [{}]})").find("'camera_angle_x' must be a finite number"), std::string::npos);
  EXPECT_NE(refused(R"({"camera_angle_x": 0.7, "frames": [{"file_path": "a"}]})").find("frames[0]: no 4 x 4 transform_matrix"), std::string::npos);
  EXPECT_NE(refused(R"({"camera_angle_x": 0.7, "frames": [{"file_path": "a", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,null],[0,0,0,1]]}]})")
                .find("transform_matrix[2][3] is not a finite number"),
            std::string::npos);
  EXPECT_NE(refused(R"({"camera_angle_x": 0.7, "frames": [{"file_path": "missing", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})")
                .find("cannot read image"),
            std::string::npos);
  std::filesystem::remove_all(folder);
}

// 100 x 100 pixels, 600 steps, 15,000 Gaussians at most: the val views (never trained on) reach
// 22 dB.
TEST(SplatTraining, GaussiansStartAtMapPointsWithTheColourTheViewsSee) {
  // A camera at the origin looking along +z at a 40 x 40 image whose left half is red, right
  // half blue; map points on a 0.1 m lattice at z = 2 (inside the view) and one behind it.
  PosedView view;
  view.camera = {40, 40, 40.0, 40.0, 19.5, 19.5, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero()};
  view.image.width = view.image.height = 40;
  for (int v = 0; v < 40; ++v) {
    for (int u = 0; u < 40; ++u) view.image.pixels.insert(view.image.pixels.end(), {u < 20 ? 1.0f : 0.0f, 0.0f, u < 20 ? 0.0f : 1.0f});
  }
  std::vector<Eigen::Vector3f> points;
  for (int i = -4; i <= 4; ++i) {
    for (int j = -4; j <= 4; ++j) points.emplace_back(0.1f * i + 0.05f, 0.1f * j, 2.0f);
  }
  points.emplace_back(0.0f, 0.0f, -1.0f);  // behind the camera: no view sees it
  const GaussianCloud all = initialize_gaussians_at_points({view}, points, 1000, 0, 1);
  ASSERT_EQ(all.size(), 81u);
  ASSERT_TRUE(all.consistent());
  for (std::size_t i = 0; i < all.size(); ++i) {
    const float x = all.position[3 * i];
    const Eigen::Vector3f colour = Eigen::Vector3f(all.sh[3 * i], all.sh[3 * i + 1], all.sh[3 * i + 2]) * 0.28209479f + Eigen::Vector3f::Constant(0.5f);
    EXPECT_NEAR(colour.x(), x < 0.0f ? 1.0f : 0.0f, 1e-4) << "point at x " << x;
    EXPECT_NEAR(colour.z(), x < 0.0f ? 0.0f : 1.0f, 1e-4) << "point at x " << x;
    EXPECT_NEAR(std::exp(all.log_scale[3 * i]), 0.1, 0.05);  // the lattice spacing (edges: its nearest three)
    EXPECT_NEAR(sigmoid(all.opacity_logit[i]), 0.1f, 1e-5);
  }
  EXPECT_EQ(initialize_gaussians_at_points({view}, points, 20, 0, 1).size(), 20u);  // at most `count`
}

TEST(SplatTraining, LegoAtQuarterResolutionScoresOnTheHeldOutViews) {
  const Result<ViewDataset> train = lego("train", 4);
  const Result<ViewDataset> val = lego("val", 4);
  ASSERT_TRUE(train && val);
  SplatTrainingConfig training;
  training.iterations = 600;
  training.initial_gaussians = 10000;
  training.max_gaussians = 15000;
  training.sh_degree_interval = 300;
  GaussianCloud initial = initialize_gaussians(train->views, train->scene_centre, 0.5 * train->camera_distance, training.initial_gaussians,
                                               training.sh_degree, training.seed);
  EXPECT_GT(initial.size(), 7500u);  // the visual hull holds the most of them
  Result<SplatTrainer> trainer = SplatTrainer::create(std::move(initial), 1.1 * train->camera_distance, training);
  ASSERT_TRUE(trainer) << trainer.error().message;
  const EvaluationSummary before = evaluate_splats(trainer->cloud(), val->views, trainer->render_config());
  std::mt19937_64 random(1);
  std::vector<std::size_t> order;
  for (int step = 0; step < training.iterations; ++step) {
    if (order.empty()) {
      order.resize(train->views.size());
      std::iota(order.begin(), order.end(), 0);
      std::shuffle(order.begin(), order.end(), random);
    }
    ASSERT_TRUE(std::isfinite(trainer->step(train->views[order.back()])));
    order.pop_back();
  }
  const EvaluationSummary after = evaluate_splats(trainer->cloud(), val->views, trainer->render_config());
  std::printf("lego 100x100 val: PSNR %.2f -> %.2f dB, SSIM %.3f -> %.3f, %zu Gaussians, %.1f ms per view\n", before.mean_psnr, after.mean_psnr,
              before.mean_ssim, after.mean_ssim, trainer->cloud().size(), 1000.0 * after.seconds_per_view);
  EXPECT_EQ(after.views.size(), 25u);
  EXPECT_GT(after.mean_psnr, 22.0);  // measured 23.4
  EXPECT_GT(after.mean_ssim, 0.85);
  EXPECT_TRUE(trainer->cloud().consistent());
}

// Points triangulated from the lego's training views (their features matched between nearby
// views, the known cameras) lie on the model: in the val views, which they never came from,
// they fall on the foreground.
TEST(ViewPoints, TriangulatedLegoPointsLieOnTheModelInUnseenViews) {
  const Result<ViewDataset> train = lego("train", 2);
  const Result<ViewDataset> val = lego("val", 2);
  ASSERT_TRUE(train && val);
  const std::vector<Eigen::Vector3f> points = triangulate_view_points(train->views);
  std::size_t seen = 0, on_model = 0;
  for (const Eigen::Vector3f& point : points) {
    for (const PosedView& view : val->views) {
      const Eigen::Vector3d p = view.camera.R_camera_world * point.cast<double>() + view.camera.t_camera_world;
      const long x = std::lround(view.camera.fx * p.x() / p.z() + view.camera.cx), y = std::lround(view.camera.fy * p.y() / p.z() + view.camera.cy);
      if (p.z() <= 0 || x < 0 || y < 0 || x >= view.camera.width || y >= view.camera.height) continue;
      ++seen;
      on_model += view.mask[static_cast<std::size_t>(y * view.camera.width + x)] > 0.5f ? 1 : 0;
    }
  }
  std::printf("lego: %zu points triangulated from 100 views at 200 x 200; %.1f %% of their %zu projections into the val views on the model\n",
              points.size(), 100.0 * static_cast<double>(on_model) / static_cast<double>(std::max<std::size_t>(seen, 1)), seen);
  EXPECT_GT(points.size(), 2000u);
  EXPECT_GT(static_cast<double>(on_model), 0.90 * static_cast<double>(seen));  // 93.3 % measured (points at the silhouette round off it)
}

}  // namespace
}  // namespace hanzo::fusion::neural
