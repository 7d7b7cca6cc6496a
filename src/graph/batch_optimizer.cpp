#include "hanzo/fusion/graph/batch_optimizer.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <type_traits>

#include <ceres/ceres.h>
#include <fmt/format.h>
#include <omp.h>

#include "hanzo/fusion/graph/pose_factors.hpp"
#include "hanzo/fusion/graph/projection_factors.hpp"

namespace hanzo::fusion::graph {
namespace {

// Parameter layouts: SE2 (x, y, theta); SE3 (tx, ty, tz, qx, qy, qz, qw); Vector3 (x, y, z);
// ImuBias (accelerometer xyz, gyroscope xyz).
int ambient_size(const Value& value) {
  return std::holds_alternative<SE3>(value) ? 7 : std::holds_alternative<ImuBias>(value) ? 6 : 3;
}
int tangent_size(const Value& value) { return std::holds_alternative<SE3>(value) || std::holds_alternative<ImuBias>(value) ? 6 : 3; }

void to_parameters(const Value& value, double* p) {
  if (const auto* se2 = std::get_if<SE2>(&value)) {
    p[0] = se2->translation().x();
    p[1] = se2->translation().y();
    p[2] = se2->angle();
  } else if (const auto* se3 = std::get_if<SE3>(&value)) {
    Eigen::Map<Eigen::Vector3d>{p} = se3->translation();
    const Eigen::Quaterniond& q = se3->rotation().quaternion();
    p[3] = q.x();
    p[4] = q.y();
    p[5] = q.z();
    p[6] = q.w();
  } else if (const auto* bias = std::get_if<ImuBias>(&value)) {
    Eigen::Map<Eigen::Matrix<double, 6, 1>>{p} = bias->vector();
  } else {
    Eigen::Map<Eigen::Vector3d>{p} = std::get<Eigen::Vector3d>(value);
  }
}

SE2 se2_from(const double* p) { return SE2(p[2], Eigen::Vector2d(p[0], p[1])); }
SE3 se3_from(const double* p) {
  return SE3(SO3::from_quaternion_normalized(Eigen::Quaterniond(p[6], p[3], p[4], p[5])), Eigen::Vector3d(p[0], p[1], p[2]));
}

Value from_parameters(const Value& like, const double* p) {
  if (std::holds_alternative<SE2>(like)) return se2_from(p);
  if (std::holds_alternative<SE3>(like)) return se3_from(p);
  if (std::holds_alternative<ImuBias>(like)) return ImuBias::from_vector(Eigen::Map<const Eigen::Matrix<double, 6, 1>>{p});
  return Eigen::Vector3d(p[0], p[1], p[2]);
}

// T (+) d = T Exp(d). The Plus Jacobian is reported as [I; 0]: the cost functions give their
// tangent-space Jacobians in the first columns of the ambient ones, so Ceres' product
// (ambient Jacobian x Plus Jacobian) is exactly the tangent-space Jacobian.
class Se2Manifold final : public ceres::Manifold {
 public:
  int AmbientSize() const override { return 3; }
  int TangentSize() const override { return 3; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    to_parameters(se2_from(x) * SE2::exp(Eigen::Vector3d(delta[0], delta[1], delta[2])), x_plus_delta);
    return true;
  }
  bool PlusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jacobian}.setIdentity();
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    Eigen::Map<Eigen::Vector3d>{y_minus_x} = (se2_from(x).inverse() * se2_from(y)).log();
    return true;
  }
  bool MinusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jacobian}.setIdentity();
    return true;
  }
};

class Se3Manifold final : public ceres::Manifold {
 public:
  int AmbientSize() const override { return 7; }
  int TangentSize() const override { return 6; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    SE3::Tangent d;
    d << delta[0], delta[1], delta[2], delta[3], delta[4], delta[5];
    to_parameters(se3_from(x) * SE3::exp(d), x_plus_delta);
    return true;
  }
  bool PlusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 7, 6, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.topRows<6>().setIdentity();
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    Eigen::Map<SE3::Tangent>{y_minus_x} = (se3_from(x).inverse() * se3_from(y)).log();
    return true;
  }
  bool MinusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 6, 7, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.leftCols<6>().setIdentity();
    return true;
  }
};

// Evaluates one Factor on the parameter blocks of its variables.
class FactorCost final : public ceres::CostFunction {
 public:
  FactorCost(FactorPointer factor, std::vector<Value> prototypes) : factor_(std::move(factor)), prototypes_(std::move(prototypes)) {
    set_num_residuals(factor_->dimension());
    for (const Value& value : prototypes_) mutable_parameter_block_sizes()->push_back(ambient_size(value));
  }

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    Values local;
    for (size_t i = 0; i < prototypes_.size(); ++i) local.insert(factor_->keys()[i], from_parameters(prototypes_[i], parameters[i]));
    std::vector<Eigen::MatrixXd> tangent_jacobians;
    const Result<Eigen::VectorXd> residual = factor_->evaluate(local, jacobians ? &tangent_jacobians : nullptr);
    if (!residual || !residual->allFinite()) return false;
    Eigen::Map<Eigen::VectorXd>{residuals, num_residuals()} = *residual;
    if (jacobians == nullptr) return true;
    for (size_t i = 0; i < prototypes_.size(); ++i) {
      if (jacobians[i] == nullptr) continue;
      const int ambient = ambient_size(prototypes_[i]);
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(jacobians[i], num_residuals(), ambient);
      J.setZero();
      J.leftCols(tangent_size(prototypes_[i])) = tangent_jacobians[i];
    }
    return true;
  }

 private:
  FactorPointer factor_;
  std::vector<Value> prototypes_;
};

// The fast path for pose-pair factors (most of a pose graph): fixed sizes, no Values lookup.
template <typename FactorType, typename Pose, int kAmbient>
class PosePairCost final : public ceres::SizedCostFunction<FactorType::Residual::RowsAtCompileTime, kAmbient, kAmbient> {
 public:
  static constexpr int kResiduals = FactorType::Residual::RowsAtCompileTime;
  static constexpr int kTangent = Pose::Tangent::RowsAtCompileTime;
  explicit PosePairCost(std::shared_ptr<const FactorType> factor) : factor_(std::move(factor)) {}

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const Pose Ti = pose_from(parameters[0]), Tj = pose_from(parameters[1]);
    typename FactorType::PoseJacobian jacobian_i, jacobian_j;
    const bool want_i = jacobians != nullptr && jacobians[0] != nullptr, want_j = jacobians != nullptr && jacobians[1] != nullptr;
    const typename FactorType::Residual r = factor_->whitened_error(Ti, Tj, want_i ? &jacobian_i : nullptr, want_j ? &jacobian_j : nullptr);
    if (!r.allFinite()) return false;
    Eigen::Map<typename FactorType::Residual>{residuals} = r;
    using AmbientJacobian = Eigen::Matrix<double, kResiduals, kAmbient, Eigen::RowMajor>;
    if (want_i) {
      Eigen::Map<AmbientJacobian> J(jacobians[0]);
      J.setZero();
      J.template leftCols<kTangent>() = jacobian_i;
    }
    if (want_j) {
      Eigen::Map<AmbientJacobian> J(jacobians[1]);
      J.setZero();
      J.template leftCols<kTangent>() = jacobian_j;
    }
    return true;
  }

 private:
  static Pose pose_from(const double* p) {
    if constexpr (std::is_same_v<Pose, SE2>) {
      return se2_from(p);
    } else {
      return se3_from(p);
    }
  }
  std::shared_ptr<const FactorType> factor_;
};

// The fast path for landmark projections (most of a visual graph): an SE3 pose and a world point.
template <typename FactorType>
class ProjectionCost final : public ceres::SizedCostFunction<FactorType::Residual::RowsAtCompileTime, 7, 3> {
 public:
  static constexpr int kResiduals = FactorType::Residual::RowsAtCompileTime;
  explicit ProjectionCost(std::shared_ptr<const FactorType> factor) : factor_(std::move(factor)) {}

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    typename FactorType::PoseJacobian d_pose;
    typename FactorType::PointJacobian d_point;
    const bool want_pose = jacobians != nullptr && jacobians[0] != nullptr, want_point = jacobians != nullptr && jacobians[1] != nullptr;
    const std::optional<typename FactorType::Residual> r = factor_->whitened_error(se3_from(parameters[0]), Eigen::Map<const Eigen::Vector3d>{parameters[1]},
                                                                                   want_pose ? &d_pose : nullptr, want_point ? &d_point : nullptr);
    if (!r || !r->allFinite()) return false;
    Eigen::Map<typename FactorType::Residual>{residuals} = *r;
    if (want_pose) {
      Eigen::Map<Eigen::Matrix<double, kResiduals, 7, Eigen::RowMajor>> J(jacobians[0]);
      J.template leftCols<6>() = d_pose;
      J.col(6).setZero();
    }
    if (want_point) Eigen::Map<Eigen::Matrix<double, kResiduals, 3, Eigen::RowMajor>>{jacobians[1]} = d_point;
    return true;
  }

 private:
  std::shared_ptr<const FactorType> factor_;
};

template <typename FactorType>
ceres::CostFunction* projection_cost(const FactorPointer& factor, const std::vector<Value>& prototypes) {
  auto typed = std::dynamic_pointer_cast<const FactorType>(factor);
  if (!typed || typed->dimension() != FactorType::Residual::RowsAtCompileTime) return nullptr;
  if (prototypes.size() != 2 || !std::holds_alternative<SE3>(prototypes[0]) || !std::holds_alternative<Eigen::Vector3d>(prototypes[1])) return nullptr;
  return new ProjectionCost<FactorType>(typed);
}

// The fast path's cost for `factor` when it is a pose-pair factor of Pose on two variables of
// that type (a factor on variables of another type keeps the generic path, whose evaluate()
// refuses them by name).
template <template <typename> class FactorTemplate, typename Pose, int kAmbient>
ceres::CostFunction* pose_pair_cost(const FactorPointer& factor, const std::vector<Value>& prototypes) {
  auto typed = std::dynamic_pointer_cast<const FactorTemplate<Pose>>(factor);
  if (!typed || typed->dimension() != FactorTemplate<Pose>::Residual::RowsAtCompileTime) return nullptr;
  if (!std::all_of(prototypes.begin(), prototypes.end(), [](const Value& value) { return std::holds_alternative<Pose>(value); })) return nullptr;
  return new PosePairCost<FactorTemplate<Pose>, Pose, kAmbient>(typed);
}

ceres::CostFunction* cost_of(const FactorPointer& factor, std::vector<Value> prototypes) {
  for (ceres::CostFunction* fast : {pose_pair_cost<BetweenFactor, SE2, 3>(factor, prototypes), pose_pair_cost<BetweenFactor, SE3, 7>(factor, prototypes),
                                    pose_pair_cost<ChordalBetweenFactor, SE2, 3>(factor, prototypes),
                                    pose_pair_cost<ChordalBetweenFactor, SE3, 7>(factor, prototypes),
                                    projection_cost<ProjectionFactor>(factor, prototypes), projection_cost<StereoProjectionFactor>(factor, prototypes)}) {
    if (fast != nullptr) return fast;
  }
  return new FactorCost(factor, std::move(prototypes));
}

// DCS as iteratively reweighted least squares (as g2o applies it): weight w = scale^2.
class DcsLoss final : public ceres::LossFunction {
 public:
  explicit DcsLoss(double phi) : phi_(phi) {}
  void Evaluate(double s, double rho[3]) const override {
    const double scale = std::min(1.0, 2.0 * phi_ / (phi_ + s));
    const double weight = scale * scale;
    rho[0] = weight * s;
    rho[1] = weight;
    rho[2] = 0.0;
  }

 private:
  double phi_;
};

ceres::LossFunction* loss_of(const RobustKernel& kernel) {
  switch (kernel.type) {
    case RobustKernel::Type::kHuber: return new ceres::HuberLoss(kernel.parameter);
    case RobustKernel::Type::kCauchy: return new ceres::CauchyLoss(kernel.parameter);
    case RobustKernel::Type::kDcs: return new DcsLoss(kernel.parameter);
    case RobustKernel::Type::kNone: break;
  }
  return nullptr;
}

// A Ceres problem holding a copy of the graph's variables as parameter blocks.
struct CeresProblem {
  CeresProblem() : problem(options()) {}
  static ceres::Problem::Options options() {
    ceres::Problem::Options problem_options;
    problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    return problem_options;
  }
  ceres::Problem problem;
  std::map<Key, std::vector<double>> blocks;
};

Status build_problem(const FactorGraph& graph, const Values& values, const std::vector<Key>& fixed, CeresProblem& built) {
  static const Se2Manifold se2_manifold;
  static const Se3Manifold se3_manifold;
  const auto block_of = [&](Key key) -> Result<double*> {
    const auto found = built.blocks.find(key);
    if (found != built.blocks.end()) return found->second.data();
    if (!values.exists(key)) return Error(fmt::format("optimize: no initial value for {}", key_to_string(key)));
    const Value& value = values.all().at(key);
    std::vector<double>& storage = built.blocks[key];
    storage.resize(static_cast<size_t>(ambient_size(value)));
    to_parameters(value, storage.data());
    ceres::Manifold* manifold = nullptr;
    if (std::holds_alternative<SE2>(value)) manifold = const_cast<Se2Manifold*>(&se2_manifold);
    if (std::holds_alternative<SE3>(value)) manifold = const_cast<Se3Manifold*>(&se3_manifold);
    built.problem.AddParameterBlock(storage.data(), static_cast<int>(storage.size()), manifold);
    return storage.data();
  };
  for (const FactorPointer& factor : graph.factors()) {
    std::vector<double*> parameters;
    std::vector<Value> prototypes;
    for (Key key : factor->keys()) {
      double* block = nullptr;
      HANZO_ASSIGN_OR_RETURN(block, block_of(key));
      parameters.push_back(block);
      prototypes.push_back(values.all().at(key));
    }
    built.problem.AddResidualBlock(cost_of(factor, std::move(prototypes)), loss_of(factor->robust_kernel()), parameters);
  }
  for (Key key : fixed) {
    const auto found = built.blocks.find(key);
    if (found == built.blocks.end()) return Error(fmt::format("optimize: the fixed variable {} is in no factor", key_to_string(key)));
    built.problem.SetParameterBlockConstant(found->second.data());
  }
  return ok_status();
}

// Runs `function` with at most `thread_limit` OpenMP threads in any parallel region it opens.
// Why: CHOLMOD (SuiteSparse 5.12, Debian 12), which Ceres' sparse Cholesky calls, opens OpenMP
// regions with a fixed 4 threads (CHOLMOD_OMP_NUM_THREADS) in every supernodal factorization,
// whatever OMP_NUM_THREADS says; the regions are tiny (copying one supernode), so on a 2-core
// machine the threads mostly wake and sleep on futexes: measured, sphere2500 2.07 -> 1.04 s and
// parking-garage 0.69 -> 0.33 s with the limit at 1. A host `teams` region with thread_limit
// sets the OpenMP thread-limit for this thread only and restores it after (libgomp runs a
// single host team on the calling thread). Inside a caller's own OpenMP parallel region a
// teams construct is not allowed, so there the function runs as it is.
template <typename Function>
void with_openmp_thread_limit(int thread_limit, Function&& function) {
  if (omp_get_level() > 0) {
    function();
    return;
  }
  const int limit = std::max(1, thread_limit);
#pragma omp teams num_teams(1) thread_limit(limit)
  function();
}

}  // namespace

Result<OptimizationSummary> optimize(const FactorGraph& graph, Values& values, const BatchOptimizerConfig& config) {
  if (!(config.initial_trust_region_radius > 0) || !std::isfinite(config.initial_trust_region_radius)) {
    return Error(fmt::format("batch optimizer: initial_trust_region_radius {} is not a positive number", config.initial_trust_region_radius));
  }
  CeresProblem built;
  HANZO_RETURN_IF_ERROR(build_problem(graph, values, config.fixed, built));
  ceres::Problem& problem = built.problem;
  std::map<Key, std::vector<double>>& blocks = built.blocks;

  ceres::Solver::Options options;
  options.trust_region_strategy_type =
      config.method == BatchOptimizerConfig::Method::kDogleg ? ceres::DOGLEG : ceres::LEVENBERG_MARQUARDT;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.max_num_iterations = config.max_iterations;
  options.initial_trust_region_radius = config.initial_trust_region_radius;
  options.function_tolerance = config.function_tolerance;
  options.gradient_tolerance = config.gradient_tolerance;
  options.parameter_tolerance = config.parameter_tolerance;
  options.num_threads = config.num_threads;
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  with_openmp_thread_limit(config.num_threads, [&] { ceres::Solve(options, &problem, &summary); });

  for (const auto& [key, storage] : blocks) values.insert(key, from_parameters(values.all().at(key), storage.data()));
  OptimizationSummary result;
  result.initial_chi2 = 2.0 * summary.initial_cost;  // robust: sum of rho(||r||^2)
  result.final_chi2 = 2.0 * summary.final_cost;
  result.iterations = static_cast<int>(summary.iterations.size()) - 1;
  result.seconds = summary.total_time_in_seconds;
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  result.message = summary.message;
  if (summary.termination_type == ceres::FAILURE) return Error(fmt::format("optimize: {}", summary.message));
  return result;
}

Result<std::vector<Eigen::MatrixXd>> marginal_covariances(const FactorGraph& graph, const Values& values, const std::vector<Key>& keys,
                                                          const BatchOptimizerConfig& config) {
  CeresProblem built;
  HANZO_RETURN_IF_ERROR(build_problem(graph, values, config.fixed, built));
  std::vector<std::pair<const double*, const double*>> pairs;
  for (Key key : keys) {
    const auto found = built.blocks.find(key);
    if (found == built.blocks.end()) return Error(fmt::format("marginal covariance: {} is in no factor", key_to_string(key)));
    pairs.emplace_back(found->second.data(), found->second.data());
  }
  ceres::Covariance::Options options;
  options.num_threads = config.num_threads;
  ceres::Covariance covariance(options);
  bool computed = false;
  with_openmp_thread_limit(config.num_threads, [&] { computed = covariance.Compute(pairs, &built.problem); });
  if (!computed) {
    return Error("marginal covariance: the information matrix is rank deficient (fix a gauge variable, constrain every variable)");
  }
  std::vector<Eigen::MatrixXd> result;
  for (Key key : keys) {
    const double* block = built.blocks.at(key).data();
    const int size = tangent_size(values.all().at(key));
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> matrix(size, size);
    covariance.GetCovarianceBlockInTangentSpace(block, block, matrix.data());
    result.emplace_back(matrix);
  }
  return result;
}

}  // namespace hanzo::fusion::graph
