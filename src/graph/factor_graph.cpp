#include "hanzo/fusion/graph/factor_graph.hpp"

#include <algorithm>
#include <cmath>

namespace hanzo::fusion::graph {

Result<double> FactorGraph::chi2(const Values& values) const {
  double sum = 0.0;
  for (const FactorPointer& factor : factors_) {
    Eigen::VectorXd residual;
    HANZO_ASSIGN_OR_RETURN(residual, factor->evaluate(values, nullptr));
    sum += residual.squaredNorm();
  }
  return sum;
}

Result<double> FactorGraph::robust_chi2(const Values& values) const {
  double sum = 0.0;
  for (const FactorPointer& factor : factors_) {
    Eigen::VectorXd residual;
    HANZO_ASSIGN_OR_RETURN(residual, factor->evaluate(values, nullptr));
    sum += factor->robust_cost(residual.squaredNorm());
  }
  return sum;
}

double Factor::robust_cost(double s) const {
  const double p = robust_kernel_.parameter;
  switch (robust_kernel_.type) {
    case RobustKernel::Type::kHuber: return s <= p * p ? s : 2.0 * p * std::sqrt(s) - p * p;
    case RobustKernel::Type::kCauchy: return p * p * std::log1p(s / (p * p));
    case RobustKernel::Type::kDcs: {
      const double scale = std::min(1.0, 2.0 * p / (p + s));
      return scale * scale * s;
    }
    case RobustKernel::Type::kNone: break;
  }
  return s;
}

}  // namespace hanzo::fusion::graph
