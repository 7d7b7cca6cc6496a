#include "hanzo/fusion/graph/incremental_smoother.hpp"

#include <optional>

#include <algorithm>
#include <chrono>
#include <limits>
#include <set>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/graph/marginalization.hpp"

namespace hanzo::fusion::graph {
namespace {

bool is_pose(const Value& value) { return std::holds_alternative<SE2>(value) || std::holds_alternative<SE3>(value); }

// The rigid correction taking `from` onto `to` (to * from^-1) applied to a value added after a
// batch snapshot: poses and points move with it, world velocities (V keys) rotate, IMU biases
// stay. 2D corrections apply to SE2 values only.
struct Correction {
  std::optional<SE2> planar;
  std::optional<SE3> spatial;

  Value apply(Key key, const Value& value) const {
    if (const auto* se2 = std::get_if<SE2>(&value)) return planar ? *planar * *se2 : value;
    if (const auto* se3 = std::get_if<SE3>(&value)) return spatial ? *spatial * *se3 : value;
    if (const auto* vector = std::get_if<Eigen::Vector3d>(&value); vector != nullptr && spatial) {
      if (symbol_character(key) == 'v') return Eigen::Vector3d(spatial->rotation() * *vector);
      return Eigen::Vector3d(*spatial * *vector);
    }
    return value;
  }
};

}  // namespace

struct IncrementalSmoother::Batch {
  std::size_t variable_count = 0;  // insertion_order_ prefix the snapshot holds
  std::size_t factor_count = 0;    // graph_.factors() prefix the snapshot holds
  std::future<Result<Values>> result;
};

IncrementalSmoother::IncrementalSmoother(IncrementalSmootherConfig config) : config_(std::move(config)) {}

IncrementalSmoother::~IncrementalSmoother() {
  if (batch_ && batch_->result.valid()) batch_->result.wait();
}

void IncrementalSmoother::start_batch() {
  batch_ = std::make_unique<Batch>();
  batch_->variable_count = insertion_order_.size();
  revision_in_last_batch_ = revision_;
  batch_->factor_count = graph_.size();
  BatchOptimizerConfig background = config_.batch;
  background.max_iterations = config_.background_max_iterations;
  batch_->result = std::async(std::launch::async, [graph = graph_, values = estimate_, config = background]() mutable -> Result<Values> {
    Result<OptimizationSummary> summary = optimize(graph, values, config);
    if (!summary) return summary.error();
    return values;
  });
}

void IncrementalSmoother::merge(Batch& batch) {
  Result<Values> solved = batch.result.get();
  if (!solved) {
    logger()->warn("incremental smoother: background batch failed, keeping the incremental estimate: {}", solved.error().message);
    return;
  }
  // The correction of the snapshot's last pose carries the variables added since.
  Correction correction;
  for (std::size_t i = batch.variable_count; i-- > 0;) {
    const Key anchor = insertion_order_[i];
    const Value& current = estimate_.all().at(anchor);
    if (!is_pose(current) || !solved->exists(anchor)) continue;
    if (const auto* se2 = std::get_if<SE2>(&current)) correction.planar = solved->at<SE2>(anchor).value() * se2->inverse();
    if (const auto* se3 = std::get_if<SE3>(&current)) correction.spatial = solved->at<SE3>(anchor).value() * se3->inverse();
    break;
  }
  for (const auto& [key, value] : solved->all()) estimate_.insert(key, value);
  for (std::size_t i = batch.variable_count; i < insertion_order_.size(); ++i) {
    const Key key = insertion_order_[i];
    estimate_.insert(key, correction.apply(key, estimate_.all().at(key)));
  }
  ++batches_merged_;
}

Result<IncrementalUpdateSummary> IncrementalSmoother::update(const FactorGraph& new_factors, const Values& new_values) {
  for (const auto& [key, value] : new_values.all()) {
    if (estimate_.exists(key)) return Error(fmt::format("incremental update: {} already exists", key_to_string(key)));
  }
  for (const FactorPointer& factor : new_factors.factors()) {
    for (Key key : factor->keys()) {
      if (!estimate_.exists(key) && !new_values.exists(key)) {
        return Error(fmt::format("incremental update: a factor refers to {}, which is neither known nor given a value", key_to_string(key)));
      }
    }
  }
  IncrementalUpdateSummary summary;
  std::optional<std::size_t> merged_factor_count;  // graph size of the merged snapshot
  if (batch_ && batch_->result.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    merge(*batch_);
    merged_factor_count = batch_->factor_count;
    batch_.reset();
    summary.batch_merged = true;
  }

  // Add, then collect the affected variables: the new factors' variables and new values, their
  // neighbours up to neighbour_hops factors away, and the most recent variables.
  std::set<Key> affected;
  for (const auto& [key, value] : new_values.all()) {
    estimate_.insert(key, value);
    insertion_order_.push_back(key);
    affected.insert(key);
  }
  for (const FactorPointer& factor : new_factors.factors()) {
    for (Key key : factor->keys()) {
      factors_of_[key].push_back(graph_.size());
      affected.insert(key);
    }
    graph_.add(factor);
  }
  if (!new_factors.factors().empty() || new_values.size() > 0) ++revision_;
  // After a merge, the variables added while the batch ran were only moved rigidly, and the
  // older variables of the factors added meanwhile (loop closures) lost their local moves to
  // the batch's solution: the factors added since the snapshot count as new (the newest first)
  // until merge_refit_variables variables are affected, where the neighbourhoods stop growing.
  std::size_t limit = std::numeric_limits<std::size_t>::max();
  if (merged_factor_count) {
    limit = std::max(affected.size(), static_cast<std::size_t>(std::max(0, config_.merge_refit_variables)));
    for (std::size_t index = graph_.size(); index-- > *merged_factor_count && affected.size() < limit;) {
      affected.insert(graph_.factors()[index]->keys().begin(), graph_.factors()[index]->keys().end());
    }
  }
  std::set<Key> frontier = affected;
  for (int hop = 0; hop < config_.neighbour_hops && affected.size() < limit; ++hop) {
    std::set<Key> next;
    for (Key key : frontier) {
      for (std::size_t index : factors_of_[key]) {
        for (Key neighbour : graph_.factors()[index]->keys()) {
          if (affected.size() < limit && affected.insert(neighbour).second) next.insert(neighbour);
        }
      }
    }
    frontier = std::move(next);
  }
  auto add_newest = [&](std::size_t count) {
    for (std::size_t i = insertion_order_.size() > count ? insertion_order_.size() - count : 0; i < insertion_order_.size(); ++i) {
      affected.insert(insertion_order_[i]);
    }
  };
  add_newest(static_cast<std::size_t>(std::max(0, config_.recent_variables)));
  // The local problem: every factor touching an affected variable; the other variables of
  // those factors (and the gauge) held constant.
  std::set<std::size_t> local_indices;
  for (Key key : affected) local_indices.insert(factors_of_[key].begin(), factors_of_[key].end());
  FactorGraph local;
  std::set<Key> local_keys;
  for (std::size_t index : local_indices) {
    local.add(graph_.factors()[index]);
    local_keys.insert(graph_.factors()[index]->keys().begin(), graph_.factors()[index]->keys().end());
  }
  BatchOptimizerConfig local_config = config_.batch;
  local_config.max_iterations = config_.local_max_iterations;
  local_config.fixed.clear();
  for (Key key : local_keys) {
    const bool gauge = std::find(config_.batch.fixed.begin(), config_.batch.fixed.end(), key) != config_.batch.fixed.end();
    if (gauge || affected.count(key) == 0) local_config.fixed.push_back(key);
  }
  summary.local_factors = static_cast<int>(local.size());
  summary.optimized_variables = static_cast<int>(local_keys.size() - local_config.fixed.size());
  if (local.size() > 0 && summary.optimized_variables > 0) {
    Result<OptimizationSummary> solved = optimize(local, estimate_, local_config);
    if (!solved) return Error(fmt::format("incremental update: {}", solved.error().message));
    summary.local_chi2_before = solved->initial_chi2;
    summary.local_chi2_after = solved->final_chi2;
  }

  if (config_.background_batch && !batch_ && revision_ != revision_in_last_batch_) {
    start_batch();
    summary.batch_started = true;
  }
  return summary;
}

std::vector<FactorPointer> IncrementalSmoother::factors_of(Key key) const {
  std::vector<FactorPointer> out;
  const auto found = factors_of_.find(key);
  if (found == factors_of_.end()) return out;
  for (std::size_t index : found->second) out.push_back(graph_.factors()[index]);
  return out;
}

Result<std::vector<Key>> IncrementalSmoother::marginalize(const std::set<Key>& keys, const std::function<bool(const Factor&)>& keep) {
  for (Key key : keys) {
    if (!estimate_.exists(key)) return Error(fmt::format("marginalize: {} is not in the graph", key_to_string(key)));
    if (std::find(config_.batch.fixed.begin(), config_.batch.fixed.end(), key) != config_.batch.fixed.end()) {
      return Error(fmt::format("marginalize: {} is held fixed (the gauge)", key_to_string(key)));
    }
  }
  if (batch_) {
    batch_->result.wait();
    merge(*batch_);
    batch_.reset();
  }
  std::set<std::size_t> touching;
  for (Key key : keys) {
    for (std::size_t index : factors_of_[key]) {
      if (!keep || !keep(*graph_.factors()[index])) touching.insert(index);
    }
  }
  std::vector<FactorPointer> removed;
  for (std::size_t index : touching) removed.push_back(graph_.factors()[index]);
  Marginalization marginal;
  HANZO_ASSIGN_OR_RETURN(marginal, graph::marginalize(removed, estimate_, keys));
  // Rebuild the graph without the removed factors and variables, the prior added last.
  FactorGraph remaining;
  for (std::size_t index = 0; index < graph_.size(); ++index) {
    if (!touching.count(index)) remaining.add(graph_.factors()[index]);
  }
  if (marginal.prior) remaining.add(marginal.prior);
  graph_ = std::move(remaining);
  factors_of_.clear();
  for (std::size_t index = 0; index < graph_.size(); ++index) {
    for (Key key : graph_.factors()[index]->keys()) factors_of_[key].push_back(index);
  }
  // Variables a kept factor still uses stay.
  std::set<Key> removed_keys;
  for (Key key : keys) {
    if (factors_of_.count(key) == 0) removed_keys.insert(key);
  }
  Values kept;
  for (const auto& [key, value] : estimate_.all()) {
    if (!removed_keys.count(key)) kept.insert(key, value);
  }
  estimate_ = std::move(kept);
  std::erase_if(insertion_order_, [&removed_keys](Key key) { return removed_keys.count(key) != 0; });
  ++revision_;
  return marginal.kept;
}

Result<OptimizationSummary> IncrementalSmoother::wait_for_batch() {
  if (batch_) {
    batch_->result.wait();
    merge(*batch_);
    batch_.reset();
  }
  OptimizationSummary summary;
  if (revision_ == revision_in_last_batch_) {
    summary.converged = true;
    summary.message = "nothing to do: the last batch covered the whole graph";
    return summary;
  }
  revision_in_last_batch_ = revision_;
  Result<OptimizationSummary> solved = optimize(graph_, estimate_, config_.batch);
  if (!solved) return Error(fmt::format("incremental smoother: final batch: {}", solved.error().message));
  return *solved;
}

}  // namespace hanzo::fusion::graph
