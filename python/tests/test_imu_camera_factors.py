"""IMU and camera factors from Python: preintegrated IMU between keyframes recovers an exact
trajectory and, with GPS positions, the IMU's biases; mono (distorted) and stereo projections
recover landmarks and poses; bad input raises ValueError naming what is wrong."""

import math

import numpy as np
import pytest

from hanzo.fusion import B, FactorGraph, ImuPreintegration, L, PinholeCamera, Pose3, V, X

GRAVITY = np.array([0.0, 0.0, -9.80665])
DT = 0.005  # 200 Hz


def hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def exp_so3(w):
    angle = np.linalg.norm(w)
    if angle < 1e-12:
        return np.eye(3) + hat(w)
    K = hat(w / angle)
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K


def simulate(seconds, bias=np.zeros(6)):
    """A 3D motion (turning on all axes, accelerating) and its IMU samples (with `bias` added),
    propagated with the same discrete model the preintegration uses, so the factors are exact.
    Returns states [(R, v, p)] at every sample and the samples [(specific_force, angular_velocity)]."""
    R, v, p = np.eye(3), np.array([1.0, 0.0, 0.0]), np.zeros(3)
    states, samples = [(R, v, p)], []
    for k in range(int(round(seconds / DT))):
        t = k * DT
        acceleration_world = np.array([math.sin(t), math.cos(0.5 * t), 0.2 * math.sin(2.0 * t)])
        angular_velocity = np.array([0.3 * math.sin(t), 0.2 * math.cos(1.3 * t), 0.4])
        specific_force = R.T @ (acceleration_world - GRAVITY)
        samples.append((specific_force + bias[:3], angular_velocity + bias[3:]))
        p = p + v * DT + 0.5 * (GRAVITY + R @ specific_force) * DT * DT
        v = v + (GRAVITY + R @ specific_force) * DT
        R = R @ exp_so3(angular_velocity * DT)
        states.append((R, v, p))
    return states, samples


def imu_graph(states, samples, keyframe_every, bias_prior_sigma):
    """Keyframes every `keyframe_every` samples: IMU factors, bias random walks, priors on the
    first pose, velocity and bias; initial values off the truth."""
    graph = FactorGraph()
    keyframes = list(range(0, len(samples) + 1, keyframe_every))
    R0, v0, p0 = states[0]
    graph.add_prior_factor(X(0), Pose3(R0, p0), np.array([1e-4] * 6))
    graph.add_prior_factor(V(0), v0, np.array([1e-4] * 3))
    graph.add_prior_factor(B(0), np.zeros(6), np.array([bias_prior_sigma] * 6))
    for i in range(1, len(keyframes)):
        preintegration = ImuPreintegration(process_noise_accel=0.05, process_noise_gyro=0.005, sample_interval=DT)
        for k in range(keyframes[i - 1], keyframes[i]):
            preintegration.integrate(samples[k][0], samples[k][1], DT)
        assert preintegration.sample_count == keyframe_every
        assert preintegration.delta_time == pytest.approx(keyframe_every * DT)
        graph.add_imu_factor(X(i - 1), V(i - 1), X(i), V(i), B(i - 1), preintegration)
        graph.add_bias_random_walk_factor(B(i - 1), B(i), keyframe_every * DT, 1e-3, 1e-4)
        R, v, p = states[keyframes[i]]
        graph.insert(X(i), Pose3(R @ exp_so3(np.array([0.03, -0.02, 0.05])), p + np.array([0.4, -0.3, 0.2])))
        graph.insert(V(i), v + np.array([0.2, 0.1, -0.1]))
        graph.insert(B(i), np.zeros(6))
    return graph, keyframes


def test_preintegrated_imu_recovers_an_exact_trajectory_from_wrong_initial_values():
    states, samples = simulate(3.0)
    graph, keyframes = imu_graph(states, samples, keyframe_every=100, bias_prior_sigma=1e-3)
    result = graph.optimize()
    assert result.converged
    for i, k in enumerate(keyframes):
        R, v, p = states[k]
        estimate = result.at(X(i))
        assert np.linalg.norm(estimate.translation() - p) < 1e-6, i
        np.testing.assert_allclose(estimate.rotation(), R, atol=1e-8)
        assert np.linalg.norm(result.at(V(i)) - v) < 1e-6, i
        assert result.at(B(i)).shape == (6,)
    # predict() chains the deltas the factor uses.
    preintegration = ImuPreintegration(process_noise_accel=0.05, process_noise_gyro=0.005, sample_interval=DT)
    for specific_force, angular_velocity in samples[:100]:
        preintegration.integrate(specific_force, angular_velocity, DT)
    pose, velocity = preintegration.predict(Pose3(states[0][0], states[0][2]), states[0][1])
    assert np.linalg.norm(pose.translation() - states[100][2]) < 1e-9
    assert np.linalg.norm(velocity - states[100][1]) < 1e-9
    assert preintegration.covariance.shape == (9, 9)


def test_imu_biases_are_estimated_with_gps_positions():
    bias = np.array([0.08, -0.05, 0.04, 0.004, -0.003, 0.005])
    states, samples = simulate(6.0, bias)
    graph, keyframes = imu_graph(states, samples, keyframe_every=50, bias_prior_sigma=1.0)
    for i, k in enumerate(keyframes):
        graph.add_gps_factor(X(i), states[k][2], np.array([0.01, 0.01, 0.01]))
    result = graph.optimize()
    estimated = np.mean([result.at(B(i)) for i in range(len(keyframes))], axis=0)
    assert np.max(np.abs(estimated[:3] - bias[:3])) < 1e-3, estimated   # m/s^2 (measured 3e-5)
    assert np.max(np.abs(estimated[3:] - bias[3:])) < 1e-5, estimated   # rad/s (measured 1e-7)
    last = len(keyframes) - 1
    assert np.linalg.norm(result.at(X(last)).translation() - states[keyframes[last]][2]) < 0.02


# Camera looking along the body's x axis: camera x = -body y, camera y = -body z, z = body x.
R_BODY_CAMERA = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def landmarks():
    rng = np.random.default_rng(7)
    return [np.array([rng.uniform(8, 15), rng.uniform(-4, 4), rng.uniform(-1, 2)]) for _ in range(20)]


def pixel_of(camera, pose, T_body_camera, point):
    point_camera = T_body_camera.inverse() * (pose.inverse() * point)
    return camera.project(point_camera)


def test_distorted_projections_recover_landmarks_and_a_pose():
    camera = PinholeCamera(400.0, 410.0, 320.0, 240.0, distortion="radtan", coefficients=[-0.2, 0.05, 0.001, -0.001, 0.01])
    assert camera.distortion == "radtan"
    T_body_camera = Pose3(R_BODY_CAMERA, np.array([0.2, 0.0, 0.5]))
    poses = [Pose3(exp_so3(np.array([0.0, 0.02 * i, 0.05 * i])), np.array([1.0 * i, 0.3 * i, 0.0])) for i in range(3)]
    points = landmarks()
    graph = FactorGraph()
    graph.add_prior_factor(X(0), poses[0], np.array([1e-6] * 6))
    graph.add_prior_factor(X(1), poses[1], np.array([1e-6] * 6))  # two known poses fix the scale
    graph.insert(X(2), poses[2] * Pose3(exp_so3(np.array([0.01, 0.02, -0.03])), np.array([0.3, -0.2, 0.1])))
    for j, point in enumerate(points):
        for i, pose in enumerate(poses):
            pixel = pixel_of(camera, pose, T_body_camera, point)
            assert pixel is not None
            graph.add_projection_factor(X(i), L(j), pixel, camera, T_body_camera, np.array([0.5, 0.5]))
        graph.insert(L(j), point + np.array([0.3, -0.3, 0.2]))
    result = graph.optimize()
    assert result.converged
    for j, point in enumerate(points):
        assert np.linalg.norm(result.at(L(j)) - point) < 1e-6, j
    assert np.linalg.norm(result.at(X(2)).translation() - poses[2].translation()) < 1e-6
    np.testing.assert_allclose(result.at(X(2)).rotation(), poses[2].rotation(), atol=1e-8)


def test_a_rectified_stereo_pair_triangulates_landmarks_from_one_pose():
    camera = PinholeCamera(450.0, 450.0, 320.0, 240.0)
    baseline = 0.12
    T_body_camera = Pose3(R_BODY_CAMERA, np.zeros(3))
    pose = Pose3(exp_so3(np.array([0.0, 0.0, 0.3])), np.array([2.0, 1.0, 0.0]))
    graph = FactorGraph()
    graph.add_prior_factor(X(0), pose, np.array([1e-6] * 6))
    points = [pose * point for point in landmarks()]
    for j, point in enumerate(points):
        left = pixel_of(camera, pose, T_body_camera, point)
        point_camera = T_body_camera.inverse() * (pose.inverse() * point)
        right_u = 450.0 * (point_camera[0] - baseline) / point_camera[2] + 320.0
        graph.add_stereo_factor(X(0), L(j), np.array([left[0], right_u, left[1]]), camera, baseline, T_body_camera, np.array([0.5] * 3))
        graph.insert(L(j), point * 1.1)
    result = graph.optimize()
    for j, point in enumerate(points):
        assert np.linalg.norm(result.at(L(j)) - point) < 1e-6, j


def test_bad_imu_and_camera_input_raises_value_error():
    with pytest.raises(ValueError, match="distortion 'fisheye'"):
        PinholeCamera(400.0, 400.0, 320.0, 240.0, distortion="fisheye")
    with pytest.raises(ValueError, match="takes 4 coefficients"):
        PinholeCamera(400.0, 400.0, 320.0, 240.0, distortion="equidistant", coefficients=[0.1])
    with pytest.raises(ValueError, match="focal lengths"):
        PinholeCamera(-400.0, 400.0, 320.0, 240.0)
    preintegration = ImuPreintegration()
    with pytest.raises(ValueError):
        preintegration.integrate(np.array([0.0, 0.0, math.nan]), np.zeros(3), DT)
    with pytest.raises(ValueError):
        preintegration.integrate(np.array([0.0, 0.0, 9.8]), np.zeros(3), 0.0)
    assert preintegration.sample_count == 0  # nothing was added
    with pytest.raises(ValueError, match="process_noise"):
        ImuPreintegration(process_noise_accel=0.0)
    graph = FactorGraph()
    with pytest.raises(ValueError, match="sample"):
        graph.add_imu_factor(X(0), V(0), X(1), V(1), B(0), preintegration)  # empty
    with pytest.raises(ValueError):
        graph.add_bias_random_walk_factor(B(0), B(1), -1.0, 1e-3, 1e-4)
    with pytest.raises(ValueError, match="rectified"):
        graph.add_stereo_factor(X(0), L(0), np.array([1.0, 2.0, 3.0]),
                                PinholeCamera(400.0, 400.0, 320.0, 240.0, "radtan", [0.1, 0.0, 0.0, 0.0]), 0.1, Pose3(), np.ones(3))
    with pytest.raises(ValueError, match="expected 6 standard deviations"):
        graph.add_prior_factor(B(0), np.zeros(6), np.ones(3))
    with pytest.raises(ValueError):
        graph.insert(B(0), np.zeros(5))
    assert len(graph) == 0
