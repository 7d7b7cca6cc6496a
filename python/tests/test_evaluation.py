"""Trajectory evaluation from Python (hanzo.fusion.ape / rpe / read_trajectory) against the
numbers evo publishes for its own test data (../shared/data/trajectory_eval_evo/SOURCE.md)."""

import json
import os
import pathlib

import numpy as np
import pytest

from hanzo.fusion import ape, read_trajectory, rpe, write_trajectory

REPO = pathlib.Path(__file__).resolve().parents[2]
EVO = pathlib.Path(os.environ.get("HANZO_DATA_DIR", REPO.parent / "shared" / "data")) / "trajectory_eval_evo"


def test_ape_and_rpe_equal_evo_on_kitti_00():
    reference = read_trajectory(str(EVO / "KITTI_00_gt.txt"), "kitti")
    estimate = read_trajectory(str(EVO / "KITTI_00_ORB.txt"), "kitti")
    assert reference.shape == estimate.shape == (4541, 8)
    stats = json.loads((EVO / "evo_reference_results" / "orb_ape_stats.json").read_text())
    result = ape(reference, estimate, alignment="se3")
    assert result["count"] == 4541
    for key in ("rmse", "mean", "median", "std", "min", "max"):
        assert result[key] == pytest.approx(stats[key], rel=1e-9), key
    evo_errors = np.loadtxt(EVO / "evo_reference_results" / "orb_ape_error_array.txt")
    np.testing.assert_allclose(result["errors"], evo_errors, rtol=1e-8, atol=1e-9)
    assert result["alignment"]["scale"] == 1.0
    rotation = result["alignment"]["rotation"]
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert result["estimate_aligned"].shape == (4541, 8)

    stats = json.loads((EVO / "evo_reference_results" / "orb_rpe_stats.json").read_text())
    result = rpe(reference, estimate, delta=10, delta_unit="m")
    assert result["count"] == len(result["pairs"]) == 353
    assert result["rmse"] == pytest.approx(stats["rmse"], rel=1e-6)


def test_ape_on_tum_fr2_desk_with_timestamps_to_associate():
    reference = read_trajectory(str(EVO / "fr2_desk_groundtruth.txt"))
    estimate = read_trajectory(str(EVO / "fr2_desk_ORB.txt"))
    result = ape(reference, estimate, alignment="se3")   # evo_ape tum ... --align
    assert result["rmse"] == pytest.approx(0.008119, abs=5e-7)
    assert result["max"] == pytest.approx(0.024300, abs=5e-7)
    mono = read_trajectory(str(EVO / "fr2_desk_ORB_kf_mono.txt"))
    unscaled = ape(reference, mono, alignment="se3")
    scaled = ape(reference, mono, alignment="sim3")
    assert scaled["alignment"]["scale"] != 1.0 and scaled["rmse"] < 0.2 * unscaled["rmse"]
    angles = ape(reference, estimate, alignment="se3", relation="angle_deg")
    assert 0 < angles["mean"] < 5


def test_trajectory_files_round_trip(tmp_path):
    poses = read_trajectory(str(EVO / "fr2_desk_ORB.txt"))
    for fmt in ("tum", "euroc"):
        path = str(tmp_path / f"poses.{fmt}")
        write_trajectory(path, poses, fmt)
        again = read_trajectory(path, fmt)
        np.testing.assert_allclose(again[:, 0], poses[:, 0], rtol=0, atol=1e-6)   # float seconds: ~0.2 us at this epoch
        np.testing.assert_allclose(again[:, 1:], poses[:, 1:], rtol=0, atol=1e-12)


def test_bad_trajectories_are_refused():
    good = np.array([[1.0, 0, 0, 0, 1, 0, 0, 0], [2.0, 1, 0, 0, 1, 0, 0, 0], [3.0, 2, 1, 0, 1, 0, 0, 0]])
    with pytest.raises(ValueError, match="8"):
        ape(good[:, :7], good)
    backwards = good[::-1].copy()
    with pytest.raises(ValueError, match="row 1: time"):
        ape(backwards, good)
    zero = good.copy()
    zero[1, 4] = 0
    with pytest.raises(ValueError, match="zero quaternion"):
        ape(good, zero)
    later = good.copy()
    later[:, 0] += 100
    with pytest.raises(ValueError, match="association"):
        ape(good, later)
    with pytest.raises(ValueError, match="alignment"):
        ape(good, good, alignment="affine")
    with pytest.raises(ValueError, match="no_such_file"):
        read_trajectory("no_such_file.txt")
    with pytest.raises(ValueError, match="format"):
        read_trajectory(str(EVO / "fr2_desk_ORB.txt"), "csv")
