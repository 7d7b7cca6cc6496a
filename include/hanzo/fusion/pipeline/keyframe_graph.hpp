#pragma once
// KeyframeGraph: the Session's backend. Keyframes from the frontend become pose nodes X(id)
// joined by between factors (the frontend's relative motion and its covariance); GNSS fixes
// attach GPS factors to the keyframe at their time; loop closures (LiDAR, visual, or manual
// through the API) add between factors with a DCS kernel, so a wrong one switches itself off.
// process() runs one IncrementalSmoother update (graph/incremental_smoother.hpp) and moves the
// session onto the optimized latest keyframe (Frontend::apply_correction), closing the loop
// between frontend and backend (after every update, or only after loop closures:
// correct_on_loop_closures_only).
//
// Frames: X(id) = T_world_body of keyframe id; factors' covariances over the SE3 tangent
// (rho, phi), right perturbation; GNSS positions in the world (ENU) frame, lever arm in the
// body frame. The first keyframe gets a prior with the frontend's covariance (converted from
// (position world, orientation body) to the tangent), which anchors the graph.
//
// With window_keyframes, the variables of keyframes older than the window besides their poses
// (velocities, biases, landmarks) are marginalized into a prior on the window: memory and the
// loop closures' batches then grow with the poses of the pose graph of older keyframes only.
//
// Use from one thread: attach() queues keyframes from the session's callback; call process()
// after Frontend::push returns (never inside a callback).

#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <set>
#include <vector>

#include "hanzo/fusion/graph/incremental_smoother.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/pipeline/frontend.hpp"

namespace hanzo::fusion::pipeline {

struct KeyframeGraphConfig {
  graph::IncrementalSmootherConfig smoother;
  double loop_closure_dcs_phi = 1000;     ///< DCS parameter of loop closures (graph/factor.hpp)
  double gps_max_time_offset_s = 0.1;    ///< a fix this close to a keyframe attaches to it
  /// Cauchy kernel of the GPS factors of add_gps_at_keyframe (whitened residual units): fixes
  /// off by multipath far beyond their covariance lose their pull.
  double gps_cauchy_scale = 2.0;
  /// GNSS errors are correlated in time (multipath, the atmosphere, a float solution's
  /// ambiguities change over seconds to minutes): fixes taken as independent pull the graph's
  /// shape along the error's wander and over-trust its average. With gnss_error_correlation_s > 0
  /// each keyframe with fixes gets an error variable E(k) (world ENU m: the receiver's position
  /// error), a first-order Gauss-Markov process with this time constant between consecutive
  /// ones (graph::GaussMarkovFactor), whose stationary covariance is the fix's reported
  /// covariance times (1 - gnss_white_fraction); each fix's factor keeps the white part (plus
  /// what the process moves between the keyframe and the fix). 0: every fix independent.
  double gnss_error_correlation_s = 10.0;
  double gnss_white_fraction = 0.1;
  /// Standard deviation (m) put under the first keyframe prior's position instead of the
  /// Frontend's own covariance; 0: the Frontend's. Where GNSS fixes give the graph its world
  /// (the Session sets it then), the Frontend's first position is a copy of the first fix, and
  /// its prior would count that fix again, with the weight of many once fixes are correlated.
  double first_position_sigma = 0.0;
  /// Run a full batch (synchronously, in process()) whenever loop closures were added. With
  /// smoother.background_batch = false this makes the backend deterministic (offline runs,
  /// tests); in real time it blocks process() for the length of a batch.
  bool batch_on_loop_closure = false;
  /// With batch_on_loop_closure: loop closures within this long (keyframe time) of the last
  /// loop closure's batch join through the incremental update only and correct the Frontend at
  /// the first update after the interval, with that update's batch (s; 0: every loop closure
  /// runs its batch). Bounds the batches' share of the time where the same places come back
  /// often (a figure eight flown over and over closes a loop every few seconds).
  double loop_batch_interval_s = 0.0;
  /// Correct the session only after updates that add loop closures (information the filter
  /// does not have). For graphs that also hold measurements the filter fused (GPS factors):
  /// moving the filter onto a smoothed estimate of its own measurements counts them twice;
  /// measured on the simulated urban drive (IMU + GNSS + wheels, multipath and an outage),
  /// correcting after every update drove the session 9.8 m RMSE off the truth (0.66 m
  /// without the graph's corrections), while the graph's keyframes with GPS factors were
  /// better than the filter's (0.44 m).
  bool correct_on_loop_closures_only = false;
  /// A full batch (synchronously, in process()) at least this often in keyframe time (s; 0:
  /// never). The incremental updates re-optimize the newest variables with the older ones held:
  /// a graph whose world comes from correlated GNSS fixes moves as a whole as the fixes add up,
  /// which only a batch spreads. For a Frontend that follows the graph in replay, where no
  /// background batch runs (smoother.background_batch false); live, background batches do it.
  double batch_interval_s = 0.0;
  /// Hold each keyframe's roll and pitch near the Frontend's (a GravityFactor: the body's "up"
  /// as the keyframe's attitude says, with its attitude covariance plus level_sigma_floor). The
  /// relative motions between keyframes carry no gravity: without this the graph keeps the
  /// tilt of its first keyframe (the start's alignment, off by the accelerometer bias) while
  /// the Frontend levels its map once turns make the bias observable. For Frontends with an
  /// IMU (the Session sets it). The filter's attitudes at successive keyframes share their
  /// errors, so each is weighted as if it were level_correlated_keyframes keyframes' worth.
  bool level_from_keyframes = false;
  double level_sigma_floor = 0.002;  ///< rad
  double level_correlated_keyframes = 10.0;
  /// Keyframes whose variables besides the pose (velocities, IMU biases, landmarks: what the
  /// visual-inertial factors add) stay in the graph; 0: every keyframe's stay. When a keyframe
  /// leaves this window its velocity, biases and the landmarks it saw are marginalized
  /// (graph/marginalization.hpp) with every factor on them and its pose's window factors
  /// (IMU, projections, the Frontend's relative motion): a prior on the window that remains.
  /// Its pose stays, as a node of the pose graph of older keyframes, with its pose-graph factors
  /// (the first keyframe's prior, GNSS, gravity, loop closures) and a link to the next
  /// keyframe: their relative pose as the window estimated it, with the Frontend's relative
  /// covariance. Memory and the cost of a loop closure's batch then grow with the keyframes'
  /// poses only, not with the landmarks.
  int window_keyframes = 0;
};

struct KeyframeGraphUpdate {
  int keyframes_added = 0;
  int factors_added = 0;
  int fixes_dropped = 0;            ///< GNSS fixes no keyframe came near
  bool corrected_session = false;   ///< apply_correction was called
  bool loop_batch = false;          ///< a full batch ran for loop closures (batch_on_loop_closure)
  int keyframes_left_window = 0;    ///< keyframes whose variables were marginalized (window_keyframes)
  std::vector<uint64_t> marginalized_landmarks;  ///< L(j) indices marginalized with them
  double correction_translation_m = 0.0;  ///< how far the correction moved the latest keyframe
};

class KeyframeGraph {
 public:
  explicit KeyframeGraph(KeyframeGraphConfig config = {});

  /// Queues the session's keyframes (replaces its keyframe callback). The graph must outlive
  /// the session's pushes.
  void attach(Frontend& frontend);

  /// Queues a keyframe: X(id) at initial_pose(), a between factor from its previous keyframe
  /// (which must be known), or a prior for the first one. Fails on an unknown previous
  /// keyframe, a repeated id or covariances that are not positive definite.
  /// relative_covariance_scale multiplies the relative motion's covariance in its between
  /// factor (a weak anchor where other factors, IMU, link the keyframes); the pose graph's link
  /// made when the keyframe leaves the window takes it unscaled.
  Status add_keyframe(const msgs::Keyframe& keyframe, double relative_covariance_scale = 1.0);
  /// Where add_keyframe() starts X(id): the previous keyframe's current estimate moved by the
  /// relative motion (so that a graph that moved away from the frontend's world, by its loop
  /// closures or its own factors, gets new keyframes where its old ones are), or the keyframe's
  /// pose for the first one.
  SE3 initial_pose(const msgs::Keyframe& keyframe) const;
  /// Queues factors and the initial values of the variables they introduce, on keyframes
  /// added so far (IMU preintegration, landmark projections: visual_inertial_factors.hpp). A
  /// value for a variable the graph already has is ignored (its estimate stays).
  void add_factors(const graph::GraphUpdate& update);
  /// A GNSS position (world ENU m, covariance m^2) at `time`, through the antenna's lever arm
  /// (body frame). Queued until process() finds the keyframe within gps_max_time_offset_s
  /// (it may be emitted after the fix); dropped, and counted, when none comes. Fails on
  /// non-finite values or a covariance that is not positive definite.
  Status add_gps(Timestamp time, const Eigen::Vector3d& position_world, const Eigen::Matrix3d& covariance,
                 const Eigen::Vector3d& lever_arm = Eigen::Vector3d::Zero());
  /// A GNSS position (world ENU m, covariance m^2) of an antenna at `lever_arm` in the body
  /// frame of keyframe `keyframe_id` (the fix's lever arm carried through the body's motion
  /// from the keyframe to the fix: any time offset between them compensated), taken
  /// seconds_from_keyframe after (or before) it. Fails for a keyframe not added yet, non-finite
  /// values or a covariance that is not positive definite.
  Status add_gps_at_keyframe(uint64_t keyframe_id, const Eigen::Vector3d& position_world, const Eigen::Matrix3d& covariance,
                             const Eigen::Vector3d& lever_arm, double seconds_from_keyframe = 0.0);
  /// A loop closure: keyframe `to` seen from keyframe `from` (T_from_to), covariance over its
  /// tangent. Both keyframes must be known.
  Status add_loop_closure(uint64_t from, uint64_t to, const SE3& T_from_to, const Eigen::Matrix<double, 6, 6>& covariance);

  /// Adds what is queued and re-optimizes; with a session, corrects it onto the optimized
  /// latest keyframe.
  Result<KeyframeGraphUpdate> process(Frontend* frontend = nullptr);

  /// The optimized pose of a keyframe added by process().
  std::optional<SE3> optimized_pose(uint64_t keyframe_id) const;
  /// The frontend's pose of a keyframe (as emitted) and its time.
  std::optional<SE3> frontend_pose(uint64_t keyframe_id) const;
  std::optional<Timestamp> keyframe_time(uint64_t keyframe_id) const;
  /// Ids of the keyframes added so far, in order.
  std::vector<uint64_t> keyframe_ids() const;
  /// The oldest keyframe whose variables besides the pose are in the graph (window_keyframes);
  /// none before the first keyframe.
  std::optional<uint64_t> window_start() const;
  /// Whether process() has anything to do: queued keyframes, factors or fixes not yet in.
  bool has_pending_work() const;
  /// Whether the next process() may correct the Frontend (a loop closure pending, or
  /// corrections after every update).
  bool may_correct_frontend() const { return loop_closure_pending_ || !config_.correct_on_loop_closures_only; }
  /// Whether the graph has the variable, queued (add_factors) or estimated.
  bool has_variable(graph::Key key) const { return pending_.values.exists(key) || smoother_.estimate().exists(key); }
  graph::IncrementalSmoother& smoother() { return smoother_; }

 private:
  KeyframeGraphConfig config_;
  graph::IncrementalSmoother smoother_;
  std::deque<msgs::Keyframe> queued_keyframes_;
  graph::GraphUpdate pending_;
  std::map<uint64_t, SE3> frontend_poses_;   // every keyframe added
  std::map<uint64_t, Timestamp> keyframe_times_;
  std::map<int64_t, uint64_t> keyframe_at_;  // timestamp ns -> keyframe id
  std::optional<uint64_t> latest_keyframe_;
  bool loop_closure_pending_ = false;
  std::optional<Timestamp> last_loop_batch_;  // keyframe time of the last loop closure's batch
  struct Fix {
    Timestamp time;
    Eigen::Vector3d position_world;
    Eigen::Vector3d lever_arm;
    Eigen::Matrix3d covariance;
  };
  std::deque<Fix> pending_fixes_;
  std::optional<Timestamp> last_periodic_batch_;  // keyframe time of the last batch_interval_s batch
  // The newest keyframe with a GNSS error variable E(k) (gnss_error_correlation_s), its time.
  std::optional<std::pair<uint64_t, Timestamp>> latest_gnss_error_;
  // The factor of a fix at keyframe_id (and, with correlated errors, E(keyframe_id) with its
  // prior or process factor when it has none yet) into pending_.
  Status add_fix_factor(uint64_t keyframe_id, const Eigen::Vector3d& position_world, const Eigen::Matrix3d& covariance,
                        const Eigen::Vector3d& lever_arm, double seconds_from_keyframe, bool robust);
  // The window (window_keyframes): its keyframes, oldest first, with their relative motion's
  // unscaled covariance for the link made when they leave; the factors that stay with a pose
  // when it leaves.
  struct WindowKeyframe {
    uint64_t id;
    std::optional<uint64_t> previous;
    Eigen::Matrix<double, 6, 6> relative_covariance;
  };
  std::deque<WindowKeyframe> window_;
  std::set<const graph::Factor*> pose_graph_factors_;
  // The newest factor in pending_ stays with its poses when they leave the window (they hold
  // it: the pointer stays valid).
  void mark_pose_graph_factor() {
    if (config_.window_keyframes > 0) pose_graph_factors_.insert(pending_.factors.factors().back().get());
  }
  Status leave_window(KeyframeGraphUpdate& update);
};

}  // namespace hanzo::fusion::pipeline
