// The hash-grid NeRF: gradients of its kernels (hash encoding, network, compositing) against
// central differences, marching over the occupancy grid, training on the NeRF-synthetic lego
// (../shared/data/nerf_lego_400) at a quarter of the resolution scored on held-out val views,
// the same field on any thread count, and exact file round trips.

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <numeric>
#include <random>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "hanzo/fusion/neural/hash_encoding.hpp"
#include "hanzo/fusion/neural/map_layers.hpp"
#include "hanzo/fusion/neural/mlp.hpp"
#include "hanzo/fusion/neural/nerf_field.hpp"
#include "hanzo/fusion/neural/nerf_trainer.hpp"
#include "hanzo/fusion/neural/occupancy_grid.hpp"
#include "hanzo/fusion/neural/surface.hpp"
#include "hanzo/fusion/neural/view_dataset.hpp"
#include "hanzo/fusion/neural/volume_rendering.hpp"

namespace hanzo::fusion::neural {
namespace {

const std::string kLego = std::string(HANZO_DATA_DIR) + "/nerf_lego_400";

std::vector<float> random_values(std::size_t count, float low, float high, std::mt19937_64& random) {
  std::uniform_real_distribution<float> uniform(low, high);
  std::vector<float> values(count);
  for (float& value : values) value = uniform(random);
  return values;
}

/// Largest |analytic - numeric| / max(1e-2, |numeric|) over `indices` of `values`, for a scalar
/// loss of the values (central differences of step `step`, in double where the loss allows).
double worst_gradient_error(std::vector<float>& values, const std::vector<float>& analytic, const std::vector<std::size_t>& indices,
                            const std::function<double()>& loss, float step) {
  double worst = 0.0;
  for (std::size_t i : indices) {
    const float saved = values[i];
    values[i] = saved + step;
    const double plus = loss();
    values[i] = saved - step;
    const double minus = loss();
    values[i] = saved;
    const double numeric = (plus - minus) / (2.0 * step);
    worst = std::max(worst, std::abs(analytic[i] - numeric) / std::max(1e-2, std::abs(numeric)));
  }
  return worst;
}

TEST(HashEncoding, GradientsMatchCentralDifferencesAndDenseLevelsInterpolateTheirVertices) {
  HashGridConfig config;
  config.levels = 6;
  config.log2_table_size = 12;  // the finer levels hash
  config.base_resolution = 4;
  config.finest_resolution = 64;
  ASSERT_TRUE(validate(config));
  const HashGrid grid(config);
  std::mt19937_64 random(3);
  std::vector<float> parameters = random_values(grid.parameter_count(), -1.0f, 1.0f, random);
  const std::size_t points = 50;
  const std::vector<float> positions = random_values(3 * points, 0.0f, 1.0f, random);
  const std::vector<float> weights = random_values(points * static_cast<std::size_t>(grid.output_width()), -1.0f, 1.0f, random);
  const auto loss = [&] {
    std::vector<float> features(weights.size());
    grid.forward(parameters.data(), positions.data(), points, features.data());
    double sum = 0.0;
    for (std::size_t i = 0; i < features.size(); ++i) sum += static_cast<double>(features[i]) * weights[i];
    return sum;
  };
  std::vector<float> gradient(parameters.size(), 0.0f);
  grid.backward(positions.data(), points, weights.data(), gradient.data());
  std::vector<std::size_t> touched;
  for (std::size_t i = 0; i < gradient.size(); ++i) {
    if (gradient[i] != 0.0f && touched.size() < 200) touched.push_back(i);
  }
  ASSERT_GT(touched.size(), 100u);
  // The loss is linear in the parameters: differences are exact up to rounding.
  EXPECT_LT(worst_gradient_error(parameters, gradient, touched, loss, 0.5f), 1e-3);

  // At a vertex of the coarsest (dense) level, the level's features are that vertex's entry.
  const float vertex[3] = {1.0f / 3.0f - 0.5f / 3.0f, 0.5f / 3.0f, 2.0f / 3.0f - 0.5f / 3.0f};  // x * 3 + 0.5 = 1, 1, 2
  std::vector<float> features(static_cast<std::size_t>(grid.output_width()));
  grid.forward(parameters.data(), vertex, 1, features.data());
  const std::size_t entry = (2 * 4 + 1) * 4 + 1;  // (z * 4 + y) * 4 + x at resolution 4
  EXPECT_NEAR(features[0], parameters[2 * entry], 1e-5);
  EXPECT_NEAR(features[1], parameters[2 * entry + 1], 1e-5);
}

/// The network in double, row by row: outputs, and the gradients of sum(output * output_weights).
struct ReferenceMlp {
  std::vector<double> output, parameter_gradient, input_gradient;
};
ReferenceMlp reference_mlp(const MlpShape& shape, const std::vector<float>& parameters, const std::vector<float>& input,
                           const std::vector<float>& output_weights, std::size_t rows) {
  ReferenceMlp result;
  result.parameter_gradient.assign(parameters.size(), 0.0);
  result.input_gradient.assign(input.size(), 0.0);
  const auto inputs_of = [&](int layer) { return layer == 0 ? shape.inputs : shape.width; };
  const auto outputs_of = [&](int layer) { return layer == shape.hidden_layers ? shape.outputs : shape.width; };
  for (std::size_t r = 0; r < rows; ++r) {
    std::vector<std::vector<double>> layer_inputs;
    std::vector<std::size_t> offsets;
    std::vector<double> x(input.begin() + static_cast<std::ptrdiff_t>(r) * shape.inputs, input.begin() + static_cast<std::ptrdiff_t>(r + 1) * shape.inputs);
    std::size_t offset = 0;
    for (int layer = 0; layer <= shape.hidden_layers; ++layer) {
      layer_inputs.push_back(x);
      offsets.push_back(offset);
      std::vector<double> y(static_cast<std::size_t>(outputs_of(layer)), 0.0);
      for (int i = 0; i < inputs_of(layer); ++i) {
        for (int j = 0; j < outputs_of(layer); ++j) y[static_cast<std::size_t>(j)] += x[static_cast<std::size_t>(i)] * parameters[offset + static_cast<std::size_t>(i * outputs_of(layer) + j)];
      }
      offset += static_cast<std::size_t>(inputs_of(layer) * outputs_of(layer));
      if (layer < shape.hidden_layers) {
        for (double& value : y) value = std::max(value, 0.0);
      }
      x = y;
    }
    result.output.insert(result.output.end(), x.begin(), x.end());
    std::vector<double> g(output_weights.begin() + static_cast<std::ptrdiff_t>(r) * shape.outputs,
                          output_weights.begin() + static_cast<std::ptrdiff_t>(r + 1) * shape.outputs);
    for (int layer = shape.hidden_layers; layer >= 0; --layer) {
      std::vector<double> dx(static_cast<std::size_t>(inputs_of(layer)), 0.0);
      for (int i = 0; i < inputs_of(layer); ++i) {
        for (int j = 0; j < outputs_of(layer); ++j) {
          const std::size_t w = offsets[static_cast<std::size_t>(layer)] + static_cast<std::size_t>(i * outputs_of(layer) + j);
          result.parameter_gradient[w] += layer_inputs[static_cast<std::size_t>(layer)][static_cast<std::size_t>(i)] * g[static_cast<std::size_t>(j)];
          dx[static_cast<std::size_t>(i)] += g[static_cast<std::size_t>(j)] * parameters[w];
        }
        if (layer > 0 && !(layer_inputs[static_cast<std::size_t>(layer)][static_cast<std::size_t>(i)] > 0.0)) dx[static_cast<std::size_t>(i)] = 0.0;
      }
      if (layer == 0) std::copy(dx.begin(), dx.end(), result.input_gradient.begin() + static_cast<std::ptrdiff_t>(r) * shape.inputs);
      g = dx;
    }
  }
  return result;
}

template <typename A, typename B>
double largest_difference(const std::vector<A>& a, const std::vector<B>& b) {
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, std::abs(static_cast<double>(a[i]) - static_cast<double>(b[i])));
  return worst;
}

TEST(Mlp, ForwardAndBackwardMatchADoubleReferenceForFixedAndRunTimeWidths) {
  // 64 and 16 wide layers run the fixed-width kernels, 7 and 3 the run-time ones; 1500 rows make
  // two blocks. (ReLU kinks make central differences unreliable for a whole network; its
  // gradients are checked against the chain rule in double instead.)
  for (const MlpShape& shape : {MlpShape{32, 64, 2, 16}, MlpShape{5, 7, 1, 3}}) {
    const Mlp network(shape);
    std::mt19937_64 random(5);
    std::vector<float> parameters(network.parameter_count());
    network.initialize(parameters.data(), random);
    const std::size_t rows = 1500;
    const std::vector<float> input = random_values(rows * static_cast<std::size_t>(shape.inputs), -1.0f, 1.0f, random);
    const std::vector<float> output_weights = random_values(rows * static_cast<std::size_t>(shape.outputs), -1.0f, 1.0f, random);
    std::vector<float> output(output_weights.size()), activations(rows * network.activation_floats());
    network.forward(parameters.data(), input.data(), rows, output.data(), activations.data());
    std::vector<float> parameter_gradient(parameters.size(), 0.0f), input_gradient(input.size());
    network.backward(parameters.data(), input.data(), activations.data(), rows, output_weights.data(), parameter_gradient.data(), input_gradient.data());
    const ReferenceMlp reference = reference_mlp(shape, parameters, input, output_weights, rows);
    EXPECT_LT(largest_difference(output, reference.output), 1e-5) << shape.width;
    EXPECT_LT(largest_difference(parameter_gradient, reference.parameter_gradient), 1e-4) << shape.width;  // sums of 1500 rows, up to about 20
    EXPECT_LT(largest_difference(input_gradient, reference.input_gradient), 1e-5) << shape.width;
    // Without kept activations the outputs are the same.
    std::vector<float> plain(output.size());
    network.forward(parameters.data(), input.data(), rows, plain.data());
    EXPECT_EQ(plain, output);
  }
}

TEST(VolumeRendering, CompositingGradientsMatchCentralDifferences) {
  std::mt19937_64 random(7);
  RaySamples samples;
  for (int ray = 0; ray < 20; ++ray) {
    for (int i = 0; i < 12; ++i) {
      samples.t.push_back(0.1f * static_cast<float>(i + 1));
      samples.dt.push_back(0.1f);
      samples.position.insert(samples.position.end(), {0.0f, 0.0f, 0.0f});
    }
    samples.ray_begin.push_back(static_cast<uint32_t>(samples.t.size()));
  }
  std::vector<float> density = random_values(samples.size(), 0.0f, 8.0f, random);
  std::vector<float> colour = random_values(3 * samples.size(), 0.0f, 1.0f, random);
  const std::vector<float> background = random_values(3 * samples.rays(), 0.0f, 1.0f, random);
  const std::vector<float> weights = random_values(3 * samples.rays(), -1.0f, 1.0f, random);
  const auto loss = [&] {
    const CompositeResult result = composite(samples, density.data(), colour.data(), background.data());
    double sum = 0.0;
    for (std::size_t i = 0; i < weights.size(); ++i) sum += static_cast<double>(result.colour[i]) * weights[i];
    return sum;
  };
  const CompositeResult result = composite(samples, density.data(), colour.data(), background.data());
  std::vector<float> density_gradient(samples.size()), colour_gradient(colour.size());
  composite_backward(samples, density.data(), colour.data(), result, weights.data(), density_gradient.data(), colour_gradient.data());
  std::vector<std::size_t> all_densities(samples.size()), all_colours(colour.size());
  std::iota(all_densities.begin(), all_densities.end(), 0);
  std::iota(all_colours.begin(), all_colours.end(), 0);
  EXPECT_LT(worst_gradient_error(density, density_gradient, all_densities, loss, 1e-2f), 2e-2);
  EXPECT_LT(worst_gradient_error(colour, colour_gradient, all_colours, loss, 1e-2f), 1e-3);
}

TEST(OccupancyGrid, MarchingKeepsOnlyOccupiedCellsOnOneLattice) {
  OccupancyGrid grid(OccupancyGridConfig{8, 0.01f, 0.95f});
  // Only the cell at (4, 4, 4) holds density.
  std::mt19937_64 random(1);
  grid.update(
      [](const float* positions, std::size_t count, float* density) {
        for (std::size_t i = 0; i < count; ++i) {
          const bool inside = positions[3 * i] >= 0.5f && positions[3 * i] < 0.625f && positions[3 * i + 1] >= 0.5f && positions[3 * i + 1] < 0.625f &&
                              positions[3 * i + 2] >= 0.5f && positions[3 * i + 2] < 0.625f;
          density[i] = inside ? 100.0f : 0.0f;
        }
      },
      0.01f, true, 1.0, random);
  EXPECT_EQ(grid.occupied_count(), 1u);
  const Eigen::Vector3f origin(-0.5f, 0.55f, 0.56f), direction(1.0f, 0.0f, 0.0f);
  float t = 0.0f, t_end = 0.0f;
  ASSERT_TRUE(OccupancyGrid::intersect(origin, direction, t, t_end));
  EXPECT_NEAR(t, 0.5f, 1e-6);
  EXPECT_NEAR(t_end, 1.5f, 1e-6);
  const float start = t;
  RaySamples samples;
  const int added = grid.march(origin, direction, 0.01f, t_end, 1000, t, samples);
  EXPECT_GE(added, 12);
  EXPECT_LE(added, 13);
  for (std::size_t i = 0; i < samples.size(); ++i) {
    EXPECT_GE(samples.position[3 * i], 0.5f - 1e-4f);
    EXPECT_LT(samples.position[3 * i], 0.625f + 1e-4f);
    const float steps = (samples.t[i] - start) / 0.01f;
    EXPECT_NEAR(steps, std::round(steps), 1e-2) << "sample " << i << " is off the lattice";
  }
}

class LegoNerf : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    ViewDatasetConfig config;
    config.downscale = 4;
    train_ = new ViewDataset(*load_transforms(kLego + "/transforms_train.json", config));
    config.every = 5;
    val_ = new ViewDataset(*load_transforms(kLego + "/transforms_val.json", config));
  }
  static void TearDownTestSuite() {
    delete train_;
    delete val_;
  }
  // A 64^3 occupancy grid: an eighth of the default's cells to refresh, enough at 100 x 100.
  static NerfField train(int iterations, int samples_per_step) {
    NerfFieldConfig field_config;
    field_config.occupancy.resolution = 64;
    set_scene_box(*train_, field_config);
    NerfTrainingConfig config;
    config.iterations = iterations;
    config.samples_per_step = samples_per_step;
    Result<NerfField> field = NerfField::create(field_config);
    EXPECT_TRUE(field);
    Result<NerfTrainer> trainer = NerfTrainer::create(std::move(*field), train_->views, config);
    EXPECT_TRUE(trainer) << trainer.error().message;
    for (int i = 0; i < iterations; ++i) trainer->step();
    return trainer->release_field();
  }
  static ViewDataset* train_;
  static ViewDataset* val_;
};
ViewDataset* LegoNerf::train_ = nullptr;
ViewDataset* LegoNerf::val_ = nullptr;

TEST_F(LegoNerf, TrainsToTheValViewsAndRoundTripsThroughItsFile) {
  // The lego's box from the cameras (no aabb_scale in the file): 0.375 x 4.03 around the origin.
  NerfFieldConfig box;
  set_scene_box(*train_, box);
  EXPECT_NEAR(box.box_half_size, 1.51, 0.05);
  constexpr int kSteps = 160;
  const NerfField field = train(kSteps, 1 << 16);
  const EvaluationSummary scores = evaluate_nerf(field, val_->views, Eigen::Vector3f::Ones());
  ASSERT_EQ(scores.views.size(), 5u);
  std::printf("lego 100 x 100, %d steps: val PSNR %.2f dB, SSIM %.3f, %zu occupied cells\n", kSteps, scores.mean_psnr, scores.mean_ssim,
              field.occupancy().occupied_count());
  EXPECT_GT(scores.mean_psnr, 21.5);  // measured 22.45
  EXPECT_GT(scores.mean_ssim, 0.8);  // measured 0.854
  // The empty space was learned empty: far fewer cells occupied than the 64^3 seen ones.
  EXPECT_LT(field.occupancy().occupied_count(), field.occupancy().cells() / 8);

  const std::filesystem::path file = std::filesystem::temp_directory_path() / "hanzo_lego.hznerf";
  ASSERT_TRUE(save_nerf(file.string(), field));
  Result<NerfField> loaded = load_nerf(file.string());
  ASSERT_TRUE(loaded) << loaded.error().message;
  const SplatCamera& camera = val_->views[0].camera;
  const NerfRender before = field.render(camera, Eigen::Vector3f::Ones());
  const NerfRender after = loaded->render(camera, Eigen::Vector3f::Ones());
  EXPECT_EQ(before.image, after.image);
  EXPECT_EQ(before.depth, after.depth);
  // The depth where the model is drawn: the lego sits about 4 units in front of the cameras.
  double depth_sum = 0.0;
  int drawn = 0;
  for (std::size_t i = 0; i < before.depth.size(); ++i) {
    if (before.opacity[i] > 0.9f) {
      depth_sum += before.depth[i];
      ++drawn;
    }
  }
  ASSERT_GT(drawn, 500);
  EXPECT_NEAR(depth_sum / drawn, 4.0, 0.6);

  // As a FusionMap layer: the same field, bit for bit.
  const Result<NerfField> from_layer = from_neural_field_layer(to_neural_field_layer(field, {"lego", 100, kSteps, 0.0, 0, 0.0, 0.0}));
  ASSERT_TRUE(from_layer) << from_layer.error().message;
  EXPECT_EQ(from_layer->render(camera, Eigen::Vector3f::Ones()).image, before.image);

  // Its surface: the density's marching-cubes mesh and the TSDF of its rendered depth at the val
  // cameras (two independent routes through the box mapping, the cameras and the meshing) agree.
  const Result<msgs::MeshLayer> surface = extract_surface(field, {128, NerfSurfaceConfig{}.density_threshold});
  ASSERT_TRUE(surface) << surface.error().message;
  const Result<maps::TsdfVolume> fused =
      fuse_rendered_depth([&field](const SplatCamera& view) { return field.render(view, Eigen::Vector3f::Ones()); }, val_->views, {0.03, 0.5});
  ASSERT_TRUE(fused) << fused.error().message;
  const msgs::MeshLayer depth_mesh = fused->extract_mesh();
  std::printf("lego surface: %zu triangles (density), %zu (rendered depth)\n", surface->triangle_indices.size() / 3, depth_mesh.triangle_indices.size() / 3);
  ASSERT_GT(surface->triangle_indices.size(), 3000u);
  ASSERT_GT(depth_mesh.vertices.size(), 500u);
  constexpr double kCell = 0.05;
  std::map<std::array<int, 3>, std::vector<Eigen::Vector3f>> cells;
  const auto cell_of = [](const Eigen::Vector3f& p) {
    return std::array<int, 3>{static_cast<int>(std::floor(p.x() / kCell)), static_cast<int>(std::floor(p.y() / kCell)), static_cast<int>(std::floor(p.z() / kCell))};
  };
  for (const Eigen::Vector3f& vertex : surface->vertices) cells[cell_of(vertex)].push_back(vertex);
  int near = 0;
  for (const Eigen::Vector3f& vertex : depth_mesh.vertices) {
    const std::array<int, 3> c = cell_of(vertex);
    bool found = false;
    for (int dz = -1; dz <= 1 && !found; ++dz) {
      for (int dy = -1; dy <= 1 && !found; ++dy) {
        for (int dx = -1; dx <= 1 && !found; ++dx) {
          const auto it = cells.find({c[0] + dx, c[1] + dy, c[2] + dz});
          if (it == cells.end()) continue;
          for (const Eigen::Vector3f& other : it->second) found = found || (other - vertex).norm() < kCell;
        }
      }
    }
    near += found ? 1 : 0;
  }
  std::printf("rendered-depth vertices within %.2f of the density surface: %.1f %%\n", kCell, 100.0 * near / depth_mesh.vertices.size());
  EXPECT_GT(near, 0.85 * static_cast<double>(depth_mesh.vertices.size()));  // measured 91.0 %

  // A cut file is refused by name.
  std::string bytes;
  {
    std::ifstream in(file, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  std::ofstream(file, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  const Result<NerfField> cut = load_nerf(file.string());
  ASSERT_FALSE(cut);
  EXPECT_NE(cut.error().message.find("truncated"), std::string::npos) << cut.error().message;
  std::filesystem::remove(file);
}

TEST_F(LegoNerf, TheSameFieldOnOneThreadAsOnEvery) {
  NerfField parallel = train(3, 1 << 14);
  NerfField serial = [] {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    return train(3, 1 << 14);
  }();
  const SplatCamera& camera = val_->views[1].camera;
  EXPECT_EQ(parallel.render(camera, Eigen::Vector3f::Ones()).image, serial.render(camera, Eigen::Vector3f::Ones()).image);
}

}  // namespace
}  // namespace hanzo::fusion::neural
