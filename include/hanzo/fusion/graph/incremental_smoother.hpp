#pragma once
// IncrementalSmoother: a factor graph that grows at keyframe rate and is kept optimized with a
// bounded cost per update (GTSAM's iSAM2 role, built on Ceres).
//
// Each update adds factors and the initial values of new variables, then re-optimizes only the
// part the change affects: the variables of the new factors, their neighbours up to
// `neighbour_hops` factors away, and the `recent_variables` most recently added variables,
// starting from the current estimate (warm start) with every other variable held constant.
// That keeps an update's time bounded by the size of the change, not of the graph.
//
// Changes that reach far (a loop closure bends every pose along the loop) are spread by a full
// batch optimization running in a background thread on a snapshot of the graph: whenever no
// batch is running and the graph changed since the last one, the next update starts one. When
// it finishes, the next update merges it: the snapshot's variables take the batch solution;
// variables added since then move with the last pose of the snapshot (their pose relative to
// it is kept; world velocities and points are rotated and moved alike), and that update
// re-optimizes everything the batch did not see (merge_refit_variables). wait_for_batch()
// finishes the work: after it the estimate is the batch optimum of the whole graph, started
// from the incremental estimate.
//
// Updates are applied in order from one thread; estimate() is the latest merged estimate.

#include <cstddef>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/factor_graph.hpp"

namespace hanzo::fusion::graph {

struct IncrementalSmootherConfig {
  int recent_variables = 50;      ///< always re-optimized: the newest variables (a window of poses)
  int neighbour_hops = 3;         ///< factor hops around the new factors' variables, >= 0
  int local_max_iterations = 6;   ///< Levenberg-Marquardt iterations of one update
  bool background_batch = true;   ///< full re-optimization on a snapshot in a worker thread
  /// Iterations of one background batch: few, so that batches (warm-started from the latest
  /// estimate) follow each other often and the estimate is never far behind the graph.
  int background_max_iterations = 3;
  /// The update that merges a finished batch also re-optimizes what the batch did not see:
  /// the variables added while it ran (only moved rigidly with the snapshot's last pose) and
  /// the older variables of the factors added meanwhile (a loop closure's old end, whose local
  /// move the batch's solution replaced), with their neighbourhoods up to neighbour_hops, at
  /// most this many variables in all (the merging update's time grows with it: about 0.1 ms a
  /// variable on city10000).
  int merge_refit_variables = 600;
  /// The gauge (variables held fixed everywhere) and the settings of the full batch
  /// (wait_for_batch() runs it to convergence).
  BatchOptimizerConfig batch;
};

struct IncrementalUpdateSummary {
  int optimized_variables = 0;   ///< variables re-optimized by this update
  int local_factors = 0;         ///< factors of the local problem
  double local_chi2_before = 0.0;
  double local_chi2_after = 0.0;
  bool batch_merged = false;     ///< a finished background batch was merged first
  bool batch_started = false;    ///< a background batch was started after the update
};

class IncrementalSmoother {
 public:
  explicit IncrementalSmoother(IncrementalSmootherConfig config = {});
  ~IncrementalSmoother();  // waits for a running batch
  IncrementalSmoother(const IncrementalSmoother&) = delete;
  IncrementalSmoother& operator=(const IncrementalSmoother&) = delete;

  /// Adds the factors and the initial values of the variables they introduce, then
  /// re-optimizes the affected part. Fails, adding nothing, when a new value's key already
  /// exists, when a factor refers to a variable neither known nor given, or when the local
  /// optimization fails.
  Result<IncrementalUpdateSummary> update(const FactorGraph& new_factors, const Values& new_values);

  /// Takes `keys` out of the graph (a sliding window's oldest variables): waits for a running
  /// batch and merges it, then replaces every factor touching them by one prior on the variables
  /// those factors also touch (graph/marginalization.hpp, at the current estimate: first-estimate
  /// Jacobians from then on). Factors `keep` selects stay as they are, with their variables: a
  /// pose that leaves a visual-inertial window but stays in the pose graph of older keyframes
  /// gives its window factors to the prior and keeps its pose-graph factors (its window copy is
  /// marginalized, the pose-graph copy stays). Fails, changing nothing, on an unknown key or a
  /// fixed (gauge) one. Returns the prior's keys (none: nothing was left to constrain).
  Result<std::vector<Key>> marginalize(const std::set<Key>& keys, const std::function<bool(const Factor&)>& keep = {});
  /// The factors touching `key`.
  std::vector<FactorPointer> factors_of(Key key) const;

  /// Waits for a running batch and merges it; then, when the graph changed since that batch
  /// began, runs one more full batch here. Afterwards the estimate is the whole graph's optimum.
  Result<OptimizationSummary> wait_for_batch();

  const Values& estimate() const { return estimate_; }
  const FactorGraph& graph() const { return graph_; }
  int batches_merged() const { return batches_merged_; }

 private:
  struct Batch;
  void merge(Batch& batch);
  void start_batch();

  IncrementalSmootherConfig config_;
  FactorGraph graph_;
  Values estimate_;
  std::vector<Key> insertion_order_;                  // keys in the order they were added
  std::map<Key, std::vector<std::size_t>> factors_of_;  // key -> indices into graph_.factors()
  std::unique_ptr<Batch> batch_;                      // the running background batch, if any
  std::size_t revision_ = 0;                          // counts the graph's changes
  std::size_t revision_in_last_batch_ = 0;            // revision_ when the last batch began
  int batches_merged_ = 0;
};

}  // namespace hanzo::fusion::graph
