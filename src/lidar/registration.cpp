#include "hanzo/fusion/lidar/registration.hpp"

#include <array>
#include <cmath>
#include <optional>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "hanzo/fusion/cloud/parallel.hpp"
#include "ndt_grid.hpp"
#include "registration_costs.hpp"

namespace hanzo::fusion::lidar {
namespace {

constexpr std::array<std::pair<RegistrationMethod, std::string_view>, 4> kMethodNames = {{
    {RegistrationMethod::kPointToPoint, "icp"},
    {RegistrationMethod::kPointToPlane, "icp-plane"},
    {RegistrationMethod::kGicp, "gicp"},
    {RegistrationMethod::kNdt, "ndt"},
}};
constexpr std::array<std::pair<RobustKernel, std::string_view>, 4> kKernelNames = {{
    {RobustKernel::kNone, "none"},
    {RobustKernel::kHuber, "huber"},
    {RobustKernel::kCauchy, "cauchy"},
    {RobustKernel::kGemanMcClure, "geman-mcclure"},
}};

template <typename Enum, size_t N>
std::string_view name_of(const std::array<std::pair<Enum, std::string_view>, N>& names, Enum value) {
  for (const auto& [candidate, name] : names) {
    if (candidate == value) return name;
  }
  return "unknown";
}

template <typename Enum, size_t N>
std::optional<Enum> value_of(const std::array<std::pair<Enum, std::string_view>, N>& names, std::string_view name) {
  for (const auto& [candidate, candidate_name] : names) {
    if (candidate_name == name) return candidate;
  }
  return std::nullopt;
}

std::vector<Eigen::Matrix3d> to_double(const std::vector<Eigen::Matrix3f>& matrices) {
  std::vector<Eigen::Matrix3d> out(matrices.size());
  for (size_t i = 0; i < matrices.size(); ++i) out[i] = matrices[i].cast<double>();
  return out;
}

// Linearizes every source point with `cost`, in parallel chunks summed in chunk order.
template <typename Cost>
NormalEquations linearize(const Cost& cost, size_t count, const SE3& T, int num_threads) {
  const PoseBlocks pose(T);
  std::vector<NormalEquations> partial(cloud::chunk_count(count));
  cloud::parallel_chunks(count, num_threads, [&](size_t chunk, size_t begin, size_t end) {
    NormalEquations local;
    for (size_t i = begin; i < end; ++i) cost.linearize(i, pose, local);
    partial[chunk] = local;
  });
  NormalEquations total;
  for (const NormalEquations& chunk : partial) total.add(chunk);
  return total;
}

// Gauss-Newton iterations of `cost` from `guess`; fills everything of the result.
template <typename Cost>
Result<RegistrationResult> gauss_newton(const Cost& cost, size_t source_size, const SE3& guess,
                                        const RegistrationConfig& config) {
  RegistrationResult result;
  result.T_target_source = guess;
  NormalEquations equations;
  for (int iteration = 1; iteration <= config.max_iterations; ++iteration) {
    equations = linearize(cost, source_size, result.T_target_source, config.num_threads);
    if (equations.correspondences < 6) {
      return Error(fmt::format("registration: {} of {} source points have a correspondence within {} m {}(need 6); "
                               "check the initial guess and that the clouds overlap",
                               equations.correspondences, source_size, config.max_correspondence_distance,
                               iteration == 1 ? "at the initial guess " : fmt::format("after {} iterations ", iteration - 1)));
    }
    // A tiny Levenberg damping keeps the step finite along unconstrained directions.
    Matrix6d damped = equations.hessian;
    damped.diagonal().array() += 1e-9 * std::max(1.0, equations.hessian.diagonal().maxCoeff());
    const Vector6d delta = damped.ldlt().solve(-equations.gradient);
    if (!delta.allFinite()) return Error(fmt::format("registration: the normal equations are singular at iteration {}", iteration));
    result.T_target_source = result.T_target_source * SE3::exp(delta);
    result.iterations = iteration;
    if (delta.head<3>().norm() < config.translation_tolerance && delta.tail<3>().norm() < config.rotation_tolerance) {
      result.converged = true;
      break;
    }
  }
  result.num_correspondences = equations.correspondences;
  result.fitness = static_cast<double>(equations.correspondences) / static_cast<double>(source_size);
  result.inlier_rmse = std::sqrt(equations.squared_distance_sum / static_cast<double>(equations.correspondences));
  result.final_cost = equations.cost;
  const double dof = std::max(1.0, static_cast<double>(equations.correspondences) - 6.0);
  const double residual_variance = std::max(equations.cost / dof, 1e-12);
  result.information = equations.hessian / residual_variance;
  result.covariance = result.information.ldlt().solve(Matrix6d::Identity());
  result.hessian_eigenvalues = Eigen::SelfAdjointEigenSolver<Matrix6d>(equations.hessian, Eigen::EigenvaluesOnly).eigenvalues();
  return result;
}

Status check_cloud(const cloud::PointCloud& cloud, const char* role) {
  if (cloud.empty()) return Error(fmt::format("registration: the {} cloud is empty", role));
  if (auto status = cloud.validate(); !status) return Error(fmt::format("registration: {} cloud: {}", role, status.error().message));
  return ok_status();
}

}  // namespace

std::string_view to_string(RegistrationMethod method) { return name_of(kMethodNames, method); }
std::optional<RegistrationMethod> registration_method_from_string(std::string_view name) { return value_of(kMethodNames, name); }
std::string_view to_string(RobustKernel kernel) { return name_of(kKernelNames, kernel); }
std::optional<RobustKernel> robust_kernel_from_string(std::string_view name) { return value_of(kKernelNames, name); }

Status RegistrationConfig::validate() const {
  const auto positive = [](double value, const char* name) -> Status {
    if (std::isfinite(value) && value > 0.0) return ok_status();
    return Error(fmt::format("RegistrationConfig.{}: {} is not > 0", name, value), name);
  };
  HANZO_RETURN_IF_ERROR(positive(max_correspondence_distance, "max_correspondence_distance"));
  for (double distance : coarse_correspondence_distances) {
    HANZO_RETURN_IF_ERROR(positive(distance, "coarse_correspondence_distances"));
  }
  HANZO_RETURN_IF_ERROR(positive(translation_tolerance, "translation_tolerance"));
  HANZO_RETURN_IF_ERROR(positive(rotation_tolerance, "rotation_tolerance"));
  HANZO_RETURN_IF_ERROR(positive(kernel_width, "kernel_width"));
  HANZO_RETURN_IF_ERROR(positive(ndt.resolution, "ndt.resolution"));
  if (ndt.coarse_levels < 0 || ndt.coarse_levels > 4) {
    return Error(fmt::format("RegistrationConfig.ndt.coarse_levels: {} is not in [0, 4]", ndt.coarse_levels), "ndt.coarse_levels");
  }
  HANZO_RETURN_IF_ERROR(positive(geometry.plane_epsilon, "geometry.plane_epsilon"));
  if (max_iterations < 1) return Error(fmt::format("RegistrationConfig.max_iterations: {} < 1", max_iterations), "max_iterations");
  if (geometry.num_neighbors < 3) {
    return Error(fmt::format("RegistrationConfig.geometry.num_neighbors: {} < 3", geometry.num_neighbors), "geometry.num_neighbors");
  }
  if (ndt.min_points_per_cell < 3) {
    return Error(fmt::format("RegistrationConfig.ndt.min_points_per_cell: {} < 3", ndt.min_points_per_cell), "ndt.min_points_per_cell");
  }
  if (!(ndt.outlier_ratio > 0.0 && ndt.outlier_ratio < 1.0)) {
    return Error(fmt::format("RegistrationConfig.ndt.outlier_ratio: {} is not in (0, 1)", ndt.outlier_ratio), "ndt.outlier_ratio");
  }
  return ok_status();
}

struct RegistrationTarget::Impl {
  RegistrationMethod method;
  cloud::PointCloud cloud;
  std::unique_ptr<cloud::KdTree> tree;            // ICP, point-to-plane, GICP
  std::vector<Eigen::Matrix3d> covariances;       // GICP
  cloud::NeighbourLists neighbours;               // when the geometry was estimated here
  std::vector<NdtGrid> ndt;                       // NDT, coarsest first
};

RegistrationTarget::RegistrationTarget(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
RegistrationTarget::~RegistrationTarget() = default;
RegistrationTarget::RegistrationTarget(RegistrationTarget&&) noexcept = default;
RegistrationTarget& RegistrationTarget::operator=(RegistrationTarget&&) noexcept = default;
RegistrationMethod RegistrationTarget::method() const { return impl_->method; }
const cloud::PointCloud& RegistrationTarget::cloud() const { return impl_->cloud; }

Result<RegistrationTarget> RegistrationTarget::create(cloud::PointCloud cloud, const RegistrationConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  HANZO_RETURN_IF_ERROR(check_cloud(cloud, "target"));
  auto impl = std::make_unique<Impl>();
  impl->method = config.method;
  if (config.method == RegistrationMethod::kNdt) {
    for (int level = config.ndt.coarse_levels; level >= 0; --level) {
      NdtConfig grid_config = config.ndt;
      grid_config.resolution = std::ldexp(config.ndt.resolution, level);
      impl->ndt.emplace_back(cloud.positions, grid_config);
    }
    if (impl->ndt.back().size() == 0) {
      return Error(fmt::format("registration: no NDT cell of {} m holds {} target points", config.ndt.resolution,
                               config.ndt.min_points_per_cell));
    }
  } else {
    impl->tree = std::make_unique<cloud::KdTree>(cloud.positions);
    const bool needs_geometry = (config.method == RegistrationMethod::kGicp && !cloud.has_covariances()) ||
                                (config.method == RegistrationMethod::kPointToPlane && !cloud.has_normals());
    if (needs_geometry) {
      cloud::LocalGeometryConfig geometry = config.geometry;
      geometry.num_threads = config.num_threads;
      cloud::estimate_local_geometry(cloud, *impl->tree, geometry, &impl->neighbours);
    }
    if (config.method == RegistrationMethod::kGicp) impl->covariances = to_double(cloud.covariances);
  }
  impl->cloud = std::move(cloud);
  return RegistrationTarget(std::move(impl));
}

namespace {

// One registration at config.max_correspondence_distance (inputs already checked).
Result<RegistrationResult> align_once(const cloud::PointCloud& source, const RegistrationTarget& target,
                                      const SE3& T_target_source_guess, const RegistrationConfig& config) {
  const RegistrationTarget::Impl& prepared = target.impl();
  std::vector<Eigen::Vector3d> positions(source.size());
  for (size_t i = 0; i < source.size(); ++i) positions[i] = source.positions[i].cast<double>();
  const float max_squared = static_cast<float>(config.max_correspondence_distance * config.max_correspondence_distance);
  const KernelSettings kernel{config.kernel, config.kernel_width};
  std::vector<uint32_t> previous(source.size(), kNoCorrespondence);
  const auto matcher = [&] { return NearestNeighborMatcher{*prepared.tree, &prepared.neighbours, max_squared, previous}; };
  switch (config.method) {
    case RegistrationMethod::kPointToPoint:
      return gauss_newton(PointToPointCost{positions, matcher(), kernel}, source.size(), T_target_source_guess, config);
    case RegistrationMethod::kPointToPlane:
      return gauss_newton(PointToPlaneCost{positions, matcher(), prepared.cloud.normals, kernel}, source.size(), T_target_source_guess,
                          config);
    case RegistrationMethod::kGicp: {
      const std::vector<Eigen::Matrix3d> source_covariances = to_double(source.covariances);  // align() made them
      return gauss_newton(GicpCost{positions, source_covariances, matcher(), prepared.covariances, kernel},
                          source.size(), T_target_source_guess, config);
    }
    case RegistrationMethod::kNdt: {
      if (static_cast<int>(prepared.ndt.size()) != config.ndt.coarse_levels + 1 ||
          prepared.ndt.back().resolution() != config.ndt.resolution) {
        return Error("registration: the target was prepared for other NDT resolutions");
      }
      SE3 guess = T_target_source_guess;
      int iterations = 0;
      for (size_t level = 0; level + 1 < prepared.ndt.size(); ++level) {  // coarse levels: their estimate seeds the next
        NdtConfig level_config = config.ndt;
        level_config.resolution = prepared.ndt[level].resolution();
        auto coarse = gauss_newton(NdtCost{positions, prepared.ndt[level], ndt_score_constants(level_config), kernel},
                                   source.size(), guess, config);
        if (!coarse) continue;  // too coarse for this cloud (no cell holds enough points): go finer
        guess = coarse->T_target_source;
        iterations += coarse->iterations;
      }
      auto result = gauss_newton(NdtCost{positions, prepared.ndt.back(), ndt_score_constants(config.ndt), kernel},
                                 source.size(), guess, config);
      if (result) result->iterations += iterations;
      return result;
    }
  }
  return Error("registration: unknown method");
}

// GICP's source without covariances: its positions with covariances from its own neighbours.
bool needs_covariances(const cloud::PointCloud& source, const RegistrationConfig& config) {
  return config.method == RegistrationMethod::kGicp && !source.has_covariances();
}

cloud::PointCloud with_covariances(const cloud::PointCloud& source, const RegistrationConfig& config) {
  cloud::PointCloud out;
  out.positions = source.positions;
  cloud::LocalGeometryConfig geometry = config.geometry;
  geometry.num_threads = config.num_threads;
  cloud::estimate_local_geometry(out, geometry);
  return out;
}

// align() with the inputs checked and GICP's source covariances present.
Result<RegistrationResult> align_checked(const cloud::PointCloud& source, const RegistrationTarget& target,
                                         const SE3& T_target_source_guess, const RegistrationConfig& config) {
  SE3 guess = T_target_source_guess;
  int iterations = 0;
  if (config.method != RegistrationMethod::kNdt) {
    for (double distance : config.coarse_correspondence_distances) {
      RegistrationConfig stage = config;
      stage.max_correspondence_distance = distance;
      auto coarse = align_once(source, target, guess, stage);
      if (!coarse) return coarse.error();
      guess = coarse->T_target_source;
      iterations += coarse->iterations;
    }
  }
  auto result = align_once(source, target, guess, config);
  if (result) result->iterations += iterations;
  return result;
}

}  // namespace

Result<RegistrationResult> align(const cloud::PointCloud& source, const RegistrationTarget& target,
                                 const SE3& T_target_source_guess, const RegistrationConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  HANZO_RETURN_IF_ERROR(check_cloud(source, "source"));
  if (target.method() != config.method) {
    return Error(fmt::format("registration: the target was prepared for {}, not {}", to_string(target.method()),
                             to_string(config.method)));
  }
  if (needs_covariances(source, config)) return align_checked(with_covariances(source, config), target, T_target_source_guess, config);
  return align_checked(source, target, T_target_source_guess, config);
}

Result<RegistrationResult> register_clouds(const cloud::PointCloud& source, const cloud::PointCloud& target,
                                           const SE3& T_target_source_guess, const RegistrationConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  HANZO_RETURN_IF_ERROR(check_cloud(source, "source"));
  // The target's tree and covariances and the source's covariances are independent: on two
  // threads or more they are prepared side by side (each tree build is sequential).
  std::optional<Result<RegistrationTarget>> prepared;
  cloud::PointCloud source_with_covariances;
  const bool source_needs_covariances = needs_covariances(source, config);
  cloud::parallel_invoke(
      config.num_threads, [&] { prepared.emplace(RegistrationTarget::create(target, config)); },
      [&] {
        if (source_needs_covariances) source_with_covariances = with_covariances(source, config);
      });
  if (!*prepared) return prepared->error();
  return align(source_needs_covariances ? source_with_covariances : source, **prepared, T_target_source_guess, config);
}

}  // namespace hanzo::fusion::lidar
