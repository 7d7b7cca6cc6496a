"""The Python API of the factor-graph backend: the spec's example, exact recovery of a noiseless
loop, GPS through a lever arm, numpy round trips and the errors bad input raises."""

import math

import numpy as np
import pytest

from hanzo.fusion import FactorGraph, Point3, Pose2, Pose3, X, geodetic_to_enu, key_to_string


def rotation_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def square_loop():
    """Ground truth: four poses around a 10 m square, turning 90 degrees at each corner."""
    return [Pose3(rotation_z(i * math.pi / 2), np.array([[0, 0], [10, 0], [10, 10], [0, 10]][i] + [0.0])) for i in range(4)]


def test_spec_example_recovers_a_loop_from_noisy_odometry():
    truth = square_loop()
    odometry_covariance = np.diag([0.1, 0.1, 0.1, 0.05, 0.05, 0.05]) ** 2
    graph = FactorGraph()
    # Odometry with a yaw error of 0.05 rad per step and 0.3 m of stretch, then the loop closure.
    for i in range(3):
        measured = truth[i].inverse() * truth[i + 1]
        drift = Pose3(rotation_z(0.05), np.array([0.3, 0.0, 0.0]))
        graph.add_between_factor(key_from=X(i), key_to=X(i + 1), measurement=measured * drift, noise=odometry_covariance)
    graph.add_between_factor(key_from=X(3), key_to=X(0), measurement=truth[3].inverse() * truth[0],
                             noise=np.diag([0.01, 0.01, 0.01, 0.005, 0.005, 0.005]) ** 2)
    assert len(graph) == 4
    result = graph.optimize()
    assert result.converged
    assert result.final_error < result.initial_error
    trajectory = [result.at(X(i)) for i in range(4)]
    assert isinstance(trajectory[0], Pose3)
    np.testing.assert_allclose(trajectory[0].matrix(), np.eye(4), atol=1e-12)  # the first pose anchors the graph
    # The loop closure spreads the drift: the last pose moves most of the way back to the truth.
    chained_error = np.linalg.norm((graph.optimize(max_iterations=0).at(X(3)).translation() - truth[3].translation()))
    optimized_error = np.linalg.norm(trajectory[3].translation() - truth[3].translation())
    assert optimized_error < 0.5 * chained_error
    covariance = result.marginal_covariance(X(2))
    assert covariance.shape == (6, 6)
    assert np.all(np.linalg.eigvalsh(covariance) > 0)


def test_gps_factors_place_poses_through_the_lever_arm():
    graph = FactorGraph()
    lever_arm = Point3(0.5, 0.0, 1.5)
    truth = [Pose3(rotation_z(0.3 * i), np.array([2.0 * i, 0.5 * i * i, 0.0])) for i in range(5)]
    for i in range(5):
        graph.add_gps_factor(key=X(i), measurement=truth[i] * lever_arm, noise=np.array([0.02, 0.02, 0.05]), lever_arm=lever_arm)
        if i > 0:
            graph.add_between_factor(X(i - 1), X(i), truth[i - 1].inverse() * truth[i], np.array([0.01] * 3 + [0.001] * 3))
    result = graph.optimize()
    for i in range(5):
        assert np.linalg.norm(result.at(X(i)).translation() - truth[i].translation()) < 1e-6
        np.testing.assert_allclose(result.at(X(i)).rotation(), truth[i].rotation(), atol=1e-6)


def test_pose_types_and_geodesy_round_trip():
    pose = Pose3.exp(np.array([1.0, -2.0, 0.5, 0.1, 0.2, -0.3]))
    np.testing.assert_allclose(Pose3.from_matrix(pose.matrix()).matrix(), pose.matrix(), atol=1e-15)
    np.testing.assert_allclose(pose.log(), [1.0, -2.0, 0.5, 0.1, 0.2, -0.3], atol=1e-12)
    np.testing.assert_allclose((pose * pose.inverse()).matrix(), np.eye(4), atol=1e-12)
    planar = Pose2(1.0, 2.0, 0.5) * Pose2(1.0, 0.0, 0.0)
    assert planar.x() == pytest.approx(1.0 + math.cos(0.5))
    assert key_to_string(X(42)) == "x42"
    east_north_up = geodetic_to_enu(47.0001, 8.0, 410.0, 47.0, 8.0, 400.0)
    assert east_north_up[0] == pytest.approx(0.0, abs=1e-6)
    assert east_north_up[1] == pytest.approx(11.1, abs=0.1)   # 1e-4 degrees of latitude
    assert east_north_up[2] == pytest.approx(10.0, abs=1e-3)


def test_bad_input_raises_value_errors():
    with pytest.raises(ValueError, match="orthonormal"):
        Pose3(np.ones((3, 3)), np.zeros(3))
    graph = FactorGraph()
    with pytest.raises(ValueError, match="6 standard deviations"):
        graph.add_between_factor(X(0), X(1), Pose3(), np.array([0.1, 0.1]))
    with pytest.raises(ValueError, match="positive definite"):
        graph.add_between_factor(X(0), X(1), Pose3(), -np.eye(6))
    with pytest.raises(ValueError, match="Pose3 or a Pose2"):
        graph.add_between_factor(X(0), X(1), "odometry", np.eye(6))
    with pytest.raises(ValueError, match="non-finite"):
        graph.add_gps_factor(X(0), Point3(math.nan, 0.0, 0.0), np.eye(3))
    assert len(graph) == 0
    graph.add_between_factor(X(0), X(1), Pose3(), np.eye(6))
    with pytest.raises(KeyError):
        graph.optimize().at(X(7))
