#include "hanzo/fusion/graph/marginalization.hpp"

#include <algorithm>
#include <cmath>
#include <map>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

namespace hanzo::fusion::graph {
namespace {

int tangent_dimension(const Value& value) {
  if (std::holds_alternative<SE3>(value) || std::holds_alternative<ImuBias>(value)) return 6;
  return 3;  // SE2, Vector3
}

// Log(x0^-1 x) of a Lie group element and its Jacobian Jr^-1 (right perturbation of x).
template <typename Group>
Result<Eigen::VectorXd> group_offset(Key key, const Group& x0, const Values& values, Eigen::MatrixXd* jacobian) {
  Group x;
  HANZO_ASSIGN_OR_RETURN(x, values.at<Group>(key));
  typename Group::Jacobian J;
  const typename Group::Tangent d = (x0.inverse() * x).log(&J);
  if (jacobian) *jacobian = J;
  return Eigen::VectorXd(d);
}

// x (-) x0 in x0's tangent and its Jacobian with respect to a right perturbation of x.
Result<Eigen::VectorXd> tangent_offset(Key key, const Value& x0, const Values& values, Eigen::MatrixXd* jacobian) {
  if (const auto* pose = std::get_if<SE3>(&x0)) return group_offset(key, *pose, values, jacobian);
  if (const auto* pose = std::get_if<SE2>(&x0)) return group_offset(key, *pose, values, jacobian);
  if (const auto* bias = std::get_if<ImuBias>(&x0)) {
    ImuBias x;
    HANZO_ASSIGN_OR_RETURN(x, values.at<ImuBias>(key));
    if (jacobian) *jacobian = Eigen::MatrixXd::Identity(6, 6);
    return Eigen::VectorXd(x.vector() - bias->vector());
  }
  Eigen::Vector3d x;
  HANZO_ASSIGN_OR_RETURN(x, values.at<Eigen::Vector3d>(key));
  if (jacobian) *jacobian = Eigen::MatrixXd::Identity(3, 3);
  return Eigen::VectorXd(x - std::get<Eigen::Vector3d>(x0));
}

// d rho(s) / d s of Factor::robust_cost: the weight of the factor's linearization (IRLS).
double robust_weight(const RobustKernel& kernel, double s) {
  const double p = kernel.parameter;
  switch (kernel.type) {
    case RobustKernel::Type::kHuber: return s <= p * p ? 1.0 : p / std::sqrt(s);
    case RobustKernel::Type::kCauchy: return 1.0 / (1.0 + s / (p * p));
    case RobustKernel::Type::kDcs: {
      const double scale = std::min(1.0, 2.0 * p / (p + s));
      return scale * scale;
    }
    case RobustKernel::Type::kNone: break;
  }
  return 1.0;
}

// The inverse of a symmetric positive semi-definite matrix over its eigenvalues above
// relative_floor times the largest (zero along the others: directions nothing constrains).
Eigen::MatrixXd pseudo_inverse(const Eigen::MatrixXd& symmetric, double relative_floor) {
  if (symmetric.size() == 0) return symmetric;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(symmetric);
  const Eigen::VectorXd& lambda = solver.eigenvalues();
  const double floor = relative_floor * std::max(lambda.maxCoeff(), 0.0);
  Eigen::VectorXd inverse = Eigen::VectorXd::Zero(lambda.size());
  for (Eigen::Index i = 0; i < lambda.size(); ++i) inverse(i) = lambda(i) > floor && lambda(i) > 0.0 ? 1.0 / lambda(i) : 0.0;
  return solver.eigenvectors() * inverse.asDiagonal() * solver.eigenvectors().transpose();
}

}  // namespace

LinearizedPriorFactor::LinearizedPriorFactor(std::vector<Key> keys, std::vector<Value> linearization_point, Eigen::MatrixXd jacobian,
                                             Eigen::VectorXd residual)
    : Factor(std::move(keys)), linearization_point_(std::move(linearization_point)), jacobian_(std::move(jacobian)), residual_(std::move(residual)) {
  int offset = 0;
  for (const Value& value : linearization_point_) {
    offsets_.push_back(offset);
    offset += tangent_dimension(value);
  }
}

Result<Eigen::VectorXd> LinearizedPriorFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  Eigen::VectorXd offset(jacobian_.cols());
  if (jacobians) jacobians->resize(keys().size());
  for (std::size_t i = 0; i < keys().size(); ++i) {
    const int size = tangent_dimension(linearization_point_[i]);
    Eigen::MatrixXd offset_jacobian;
    Eigen::VectorXd d;
    HANZO_ASSIGN_OR_RETURN(d, tangent_offset(keys()[i], linearization_point_[i], values, jacobians ? &offset_jacobian : nullptr));
    offset.segment(offsets_[i], size) = d;
    if (jacobians) (*jacobians)[i] = jacobian_.middleCols(offsets_[i], size) * offset_jacobian;
  }
  return Eigen::VectorXd(residual_ + jacobian_ * offset);
}

Result<Marginalization> marginalize(const std::vector<FactorPointer>& factors, const Values& values, const std::set<Key>& marginalized,
                                    const MarginalizationConfig& config) {
  for (Key key : marginalized) {
    if (!values.exists(key)) return Error(fmt::format("marginalize: no value for {}", key_to_string(key)));
  }
  // Marginalized variables that share no factor with each other (landmarks, as a rule: each
  // only touches the poses that saw it) are eliminated first, one small block at a time; the
  // rest of the marginalized variables and the blanket form a dense system.
  std::map<Key, std::set<Key>> neighbours;
  std::set<Key> kept_set;
  for (const FactorPointer& factor : factors) {
    for (Key key : factor->keys()) {
      if (!values.exists(key)) return Error(fmt::format("marginalize: no value for {}", key_to_string(key)));
      if (!marginalized.count(key)) kept_set.insert(key);
      for (Key other : factor->keys()) {
        if (other != key) neighbours[key].insert(other);
      }
    }
  }
  std::vector<Key> ordered(marginalized.begin(), marginalized.end());
  std::stable_partition(ordered.begin(), ordered.end(), [](Key key) { return symbol_character(key) == 'l'; });
  std::set<Key> independent;
  for (Key key : ordered) {
    const std::set<Key>& around = neighbours[key];
    if (std::none_of(around.begin(), around.end(), [&](Key other) { return independent.count(other) != 0; })) independent.insert(key);
  }
  // Dense part: the other marginalized variables first, then the blanket.
  std::map<Key, int> dense_offset;
  int dense_size = 0;
  for (Key key : marginalized) {
    if (independent.count(key)) continue;
    dense_offset[key] = dense_size;
    dense_size += tangent_dimension(values.all().at(key));
  }
  const int marginal_size = dense_size;
  for (Key key : kept_set) {
    dense_offset[key] = dense_size;
    dense_size += tangent_dimension(values.all().at(key));
  }
  struct Block {
    Eigen::MatrixXd H;                      // its own information
    Eigen::VectorXd g;
    std::map<Key, Eigen::MatrixXd> cross;  // H_(dense key, this)
  };
  std::map<Key, Block> blocks;
  for (Key key : independent) {
    const int size = tangent_dimension(values.all().at(key));
    blocks[key] = {Eigen::MatrixXd::Zero(size, size), Eigen::VectorXd::Zero(size), {}};
  }
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(dense_size, dense_size);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(dense_size);
  for (const FactorPointer& factor : factors) {
    std::vector<Eigen::MatrixXd> jacobians;
    Eigen::VectorXd r;
    HANZO_ASSIGN_OR_RETURN(r, with_context(factor->evaluate(values, &jacobians), "marginalize"));
    if (!r.allFinite()) return Error("marginalize: a factor's residual is not finite");
    const double weight = robust_weight(factor->robust_kernel(), r.squaredNorm());
    const std::vector<Key>& keys = factor->keys();
    for (std::size_t a = 0; a < keys.size(); ++a) {
      const Eigen::MatrixXd Jt = weight * jacobians[a].transpose();
      const auto block = blocks.find(keys[a]);
      if (block != blocks.end()) {
        block->second.g += Jt * r;
      } else {
        g.segment(dense_offset.at(keys[a]), Jt.rows()) += Jt * r;
      }
      for (std::size_t b = 0; b < keys.size(); ++b) {
        const Eigen::MatrixXd product = Jt * jacobians[b];
        const bool a_block = block != blocks.end(), b_block = blocks.count(keys[b]) != 0;
        if (a_block && b_block) {
          block->second.H += product;  // the same variable: independent ones share no factor
        } else if (b_block) {
          Eigen::MatrixXd& cross = blocks.at(keys[b]).cross[keys[a]];
          if (cross.size() == 0) cross = Eigen::MatrixXd::Zero(product.rows(), product.cols());
          cross += product;
        } else if (!a_block) {
          H.block(dense_offset.at(keys[a]), dense_offset.at(keys[b]), product.rows(), product.cols()) += product;
        }
      }
    }
  }
  // Stage 1: each independent block eliminated into the dense system.
  for (const auto& [key, block] : blocks) {
    const Eigen::MatrixXd inverse = pseudo_inverse(block.H, config.relative_eigenvalue_floor);
    for (const auto& [p, cross_p] : block.cross) {
      const Eigen::MatrixXd left = cross_p * inverse;
      g.segment(dense_offset.at(p), left.rows()) -= left * block.g;
      for (const auto& [q, cross_q] : block.cross) {
        H.block(dense_offset.at(p), dense_offset.at(q), left.rows(), cross_q.rows()) -= left * cross_q.transpose();
      }
    }
  }
  Marginalization out;
  out.kept.assign(kept_set.begin(), kept_set.end());
  const int kept_size = dense_size - marginal_size;
  if (kept_size == 0) return out;
  // Stage 2: the dense Schur complement.
  const Eigen::MatrixXd H_mm_inverse = pseudo_inverse(H.topLeftCorner(marginal_size, marginal_size), config.relative_eigenvalue_floor);
  const Eigen::MatrixXd H_bm = H.bottomLeftCorner(kept_size, marginal_size);
  Eigen::MatrixXd H_b = H.bottomRightCorner(kept_size, kept_size) - H_bm * H_mm_inverse * H_bm.transpose();
  H_b = 0.5 * (H_b + H_b.transpose());
  const Eigen::VectorXd g_b = g.tail(kept_size) - H_bm * H_mm_inverse * g.head(marginal_size);
  // H_b = J0^T J0 and J0^T r0 = g_b: J0 = S^1/2 V^T, r0 = S^-1/2 V^T g_b over the kept eigenvalues.
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> blanket(H_b);
  const Eigen::VectorXd& sigma = blanket.eigenvalues();
  const double sigma_floor = config.relative_eigenvalue_floor * std::max(sigma.maxCoeff(), 0.0);
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < sigma.size(); ++i) {
    if (sigma(i) > sigma_floor && sigma(i) > 0.0) rows.push_back(i);
  }
  if (rows.empty()) return out;
  Eigen::MatrixXd J0(static_cast<Eigen::Index>(rows.size()), kept_size);
  Eigen::VectorXd r0(static_cast<Eigen::Index>(rows.size()));
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const Eigen::Index i = rows[k];
    const double root = std::sqrt(sigma(i));
    J0.row(static_cast<Eigen::Index>(k)) = root * blanket.eigenvectors().col(i).transpose();
    r0(static_cast<Eigen::Index>(k)) = blanket.eigenvectors().col(i).dot(g_b) / root;
  }
  std::vector<Value> point;
  point.reserve(out.kept.size());
  for (Key key : out.kept) point.push_back(values.all().at(key));
  out.prior = std::make_shared<LinearizedPriorFactor>(out.kept, std::move(point), std::move(J0), std::move(r0));
  return out;
}

}  // namespace hanzo::fusion::graph
