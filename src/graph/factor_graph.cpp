#include "hanzo/fusion/graph/factor_graph.hpp"

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

}  // namespace hanzo::fusion::graph
