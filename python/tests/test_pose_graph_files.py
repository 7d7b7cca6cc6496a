"""Pose-graph files and the incremental smoother from Python: intel.g2o (SE-Sync's benchmark,
published optimum 52.3482) batch and pose by pose; g2o round trip; bad input."""

import math
import os
import pathlib

import numpy as np
import pytest

from hanzo.fusion import FactorGraph, IncrementalSmoother, Pose2, X, read_g2o

DATA = pathlib.Path(os.environ.get("HANZO_DATA_DIR", pathlib.Path(__file__).resolve().parents[3] / "shared" / "data"))
INTEL = DATA / "pose_graph" / "se_sync" / "intel.g2o"
INTEL_OPTIMUM = 52.3482  # SE-Sync's F(x) (pose_graph/SOURCE.md)


@pytest.mark.skipif(not INTEL.exists(), reason="shared pose-graph data not present")
def test_intel_reaches_the_published_optimum_and_round_trips(tmp_path):
    graph = read_g2o(str(INTEL), objective="chordal")
    assert len(graph) == 2512
    result = graph.optimize()
    assert result.converged
    assert abs(result.se_sync_objective() - INTEL_OPTIMUM) / INTEL_OPTIMUM < 1e-3
    geodesic = read_g2o(str(INTEL)).optimize()
    assert geodesic.g2o_chi2() < 0.1 * geodesic.initial_error
    from_chordal = graph.optimize(initialization="chordal")
    assert abs(from_chordal.se_sync_objective() - INTEL_OPTIMUM) / INTEL_OPTIMUM < 1e-3
    certificate = from_chordal.certificate()
    assert certificate["certified"], certificate["message"]
    assert certificate["min_eigenvalue"] >= -1e-6
    assert certificate["se_sync_objective"] == pytest.approx(INTEL_OPTIMUM, rel=1e-5)
    # Written and read back: the optimized vertices are the new initial values (already optimal).
    out = tmp_path / "intel_optimized.g2o"
    result.write_g2o(str(out))
    again = read_g2o(str(out), objective="chordal").optimize(max_iterations=1)
    assert again.se_sync_objective() == pytest.approx(result.se_sync_objective(), rel=1e-4)


def test_incremental_smoother_follows_a_square_loop_pose_by_pose():
    # A 4 x 4 m square driven twice with 0.02 rad of heading error per step; the loop closures bring the
    # second lap onto the first.
    smoother = IncrementalSmoother(recent_variables=10, background_batch=False)
    first = FactorGraph()
    first.add_prior_factor(X(0), Pose2(0.0, 0.0, 0.0), np.array([1e-3, 1e-3, 1e-4]))
    smoother.update(first)
    truth = [Pose2(0.0, 0.0, 0.0)]
    estimate = Pose2(0.0, 0.0, 0.0)
    step = Pose2(1.0, 0.0, 0.0)
    turn = Pose2(1.0, 0.0, math.pi / 2)
    for i in range(1, 33):
        move = turn if i % 4 == 0 else step
        truth.append(truth[-1] * move)
        measured = Pose2(move.x(), move.y(), move.theta() + 0.02)  # a gyro bias
        estimate = estimate * measured
        update = FactorGraph()
        update.add_between_factor(X(i - 1), X(i), measured, np.array([0.05, 0.05, 0.01]))
        update.insert(X(i), estimate)
        if i >= 16:  # second lap: the same place as 16 poses earlier
            update.add_between_factor(X(i - 16), X(i), Pose2(0.0, 0.0, 0.0), np.array([0.01, 0.01, 0.002]))
        summary = smoother.update(update)
        assert summary["local_chi2_after"] <= summary["local_chi2_before"] + 1e-9
    assert len(smoother) == 33
    smoother.wait_for_batch()
    last = smoother.at(X(32))
    drift = np.hypot(estimate.x() - truth[32].x(), estimate.y() - truth[32].y())
    error = np.hypot(last.x() - truth[32].x(), last.y() - truth[32].y())
    assert drift > 0.3
    assert error < 0.5 * drift


def test_bad_files_and_updates_raise_value_errors(tmp_path):
    with pytest.raises(ValueError, match="missing.g2o"):
        read_g2o(str(tmp_path / "missing.g2o"))
    broken = tmp_path / "broken.g2o"
    broken.write_text("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0 nan 1 0 0 1 0 1\n")
    with pytest.raises(ValueError):
        read_g2o(str(broken))
    with pytest.raises(ValueError, match="objective"):
        read_g2o(str(broken), objective="l1")
    with pytest.raises(ValueError, match="initialization"):
        FactorGraph().optimize(initialization="magic")
    with pytest.raises(ValueError, match="chordal"):
        FactorGraph().optimize(initialization="chordal")
    smoother = IncrementalSmoother(background_batch=False)
    orphan = FactorGraph()
    orphan.add_between_factor(X(0), X(1), Pose2(1.0, 0.0, 0.0), np.array([0.1, 0.1, 0.01]))
    with pytest.raises(ValueError):
        smoother.update(orphan)  # neither pose has a value
    with pytest.raises(KeyError):
        smoother.at(X(5))
