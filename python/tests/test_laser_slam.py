"""2D laser SLAM from Python on the real Intel Research Lab log (docs/laser-slam.md)."""

import math
import os

import numpy as np
import pytest

from hanzo.fusion import PlanarLaserSlam, Pose2, read_carmen

DATA = os.environ.get("HANZO_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data"))
INTEL = os.path.join(DATA, "laser2d_carmen", "intel-corrected.log.gz")


def rigid_rmse(estimate, reference):
    """Position RMSE after the least-squares rotation + translation (Umeyama without scale)."""
    a, b = estimate - estimate.mean(0), reference - reference.mean(0)
    u, _, vt = np.linalg.svd(b.T @ a)
    d = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])
    aligned = (u @ d @ vt @ a.T).T
    return float(np.sqrt(((aligned - b) ** 2).sum(1).mean()))


def corrupted_odometry(poses, scale_error=0.05, drift_per_meter=math.radians(2.0)):
    """Each step 5 % too long and turning 2 deg per metre too much (what slam2d --scale-error does)."""
    out = [Pose2(*poses[0])]
    for previous, current in zip(poses[:-1], poses[1:]):
        step = Pose2(*previous).inverse() * Pose2(*current)
        length = math.hypot(step.x(), step.y())
        out.append(out[-1] * Pose2((1 + scale_error) * step.x(), (1 + scale_error) * step.y(), step.theta() + drift_per_meter * length))
    return out


def test_intel_first_300_scans_come_back_to_the_logged_poses():
    log = read_carmen(INTEL)
    assert len(log) == 906 and log.poses.shape == (906, 3) and log.scans[0].shape[1] == 2
    count = 300
    odometry = corrupted_odometry(log.poses[:count])
    slam = PlanarLaserSlam()
    for i in range(count):
        estimate = slam.add_scan(log.times[i], log.scans[i], odometry[i])
        assert estimate.scan_matched
    slam.finish()
    times, poses = slam.trajectory()
    assert len(times) == count and poses.shape == (count, 3)
    reference = log.poses[:count, :2]
    odometry_xy = np.array([[p.x(), p.y()] for p in odometry])
    assert rigid_rmse(odometry_xy, reference) > 1.0
    assert rigid_rmse(poses[:, :2], reference) < 0.15
    summary = slam.summary()
    assert summary["scans"] == count and summary["loop_closures"] > 10


def test_bad_scans_raise_and_change_nothing():
    log = read_carmen(INTEL)
    slam = PlanarLaserSlam(loop_closure=False)
    slam.add_scan(log.times[0], log.scans[0], Pose2(*log.poses[0]))
    with pytest.raises(ValueError, match="does not increase"):
        slam.add_scan(log.times[0], log.scans[1], Pose2(*log.poses[1]))
    with pytest.raises(ValueError, match="has 2 points"):
        slam.add_scan(log.times[1], np.array([[1.0, 0.0], [2.0, 0.0]]), Pose2(*log.poses[1]))
    bad = log.scans[1].copy()
    bad[5, 0] = float("nan")
    with pytest.raises(ValueError, match="non-finite point"):
        slam.add_scan(log.times[1], bad, Pose2(*log.poses[1]))
    assert slam.summary()["scans"] == 1
    with pytest.raises(ValueError, match="cannot open"):
        read_carmen("/nonexistent/log.gz")
