"""3D LiDAR odometry from Python on synthetic 16-ring sweeps inside a room (docs/lidar-odometry.md)."""

import math

import numpy as np
import pytest

from hanzo.fusion import LidarOdometry, Pose3

# A 20 m x 12 m x 5 m room (floor z = 0) with a 1 m x 1 m pillar: every direction constrained.
ROOM_MIN, ROOM_MAX = np.array([-8.0, -5.0, 0.0]), np.array([12.0, 7.0, 5.0])
PILLAR_MIN, PILLAR_MAX = np.array([3.0, 2.0, 0.0]), np.array([4.0, 3.0, 5.0])


def box_exit(origin, directions, low, high):
    """Distance to the inside wall of box [low, high] along each direction (origin inside)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(directions > 0, (high - origin) / directions, (low - origin) / directions)
    return np.nanmin(np.where(np.isfinite(t) & (t > 0), t, np.inf), axis=1)


def box_entry(origin, directions, low, high):
    """Distance to the outside of box [low, high] along each direction, inf when missed."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (low - origin) / directions, (high - origin) / directions
    near, far = np.nanmax(np.minimum(t1, t2), axis=1), np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((near <= far) & (near > 0), near, np.inf)


def sweep(x, y, yaw, rng):
    """A static 16-ring x 900-column sweep from a sensor 1 m above the floor, ranges with 1 cm noise."""
    rings = np.repeat(np.arange(16), 900)
    azimuth = np.tile(np.linspace(-math.pi, math.pi, 900, endpoint=False), 16)
    elevation = np.radians(-15.0 + 2.0 * rings)
    local = np.stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)], axis=1)
    c, s = math.cos(yaw), math.sin(yaw)
    world = local @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    origin = np.array([x, y, 1.0])
    ranges = np.minimum(box_exit(origin, world, ROOM_MIN, ROOM_MAX), box_entry(origin, world, PILLAR_MIN, PILLAR_MAX))
    ranges = ranges + rng.normal(0.0, 0.01, ranges.shape)
    return local * ranges[:, None], rings


def test_recovers_a_walk_through_the_room_to_centimetres():
    rng = np.random.default_rng(3)
    odometry = LidarOdometry(voxel=0.5, source_voxel=0.25, initial_pose=Pose3(np.eye(3), [0.0, 0.0, 1.0]))
    truth = [(0.25 * k, 0.05 * k, math.radians(2.0 * k)) for k in range(16)]
    for k, (x, y, yaw) in enumerate(truth):
        points, rings = sweep(x, y, yaw, rng)
        estimate = odometry.add_scan(100.0 + 0.1 * k, points, rings=rings.tolist())
        assert not estimate.degenerate
    x, y, yaw = truth[-1]
    assert np.linalg.norm(odometry.pose.translation() - np.array([x, y, 1.0])) < 0.03
    rotation = odometry.pose.rotation()
    heading = math.atan2(rotation[1, 0], rotation[0, 0])
    assert abs(heading - yaw) < math.radians(0.3)
    assert odometry.scans == 16
    assert odometry.map_points().shape[1] == 3


def test_bad_sweeps_raise_and_change_nothing():
    rng = np.random.default_rng(4)
    odometry = LidarOdometry(voxel=0.5, source_voxel=0.25, initial_pose=Pose3(np.eye(3), [0.0, 0.0, 1.0]))
    points, rings = sweep(0.0, 0.0, 0.0, rng)
    odometry.add_scan(100.0, points, rings=rings.tolist())
    with pytest.raises(ValueError, match="not after"):
        odometry.add_scan(100.0, points, rings=rings.tolist())
    broken = points.copy()
    broken[5, 0] = float("nan")
    with pytest.raises(ValueError, match="nan"):
        odometry.add_scan(100.1, broken)
    with pytest.raises(ValueError, match="one value per point"):
        odometry.add_scan(100.1, points, times=[0.0])
    with pytest.raises(ValueError):
        LidarOdometry(voxel=-1.0)
    assert odometry.scans == 1
