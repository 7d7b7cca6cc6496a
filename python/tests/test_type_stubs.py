"""The package's type stubs (_fusion.pyi, py.typed): mypy checks user code against them and
catches a wrong argument."""

import pathlib
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("mypy")

USAGE = """
import numpy as np
from hanzo.fusion import FactorGraph, Imu, Pose3, Session, X, ape, read_log

def optimized_x1() -> Pose3:
    graph = FactorGraph()
    graph.add_prior_factor(X(0), Pose3(np.eye(3), np.zeros(3)), np.array([0.01] * 6))
    graph.add_between_factor(X(0), X(1), Pose3(np.eye(3), np.array([1.0, 0, 0])), np.array([0.1] * 6))
    pose = graph.optimize().at(X(1))   # Pose3, Pose2 or a numpy vector, by the variable
    assert isinstance(pose, Pose3)
    return pose

def replayed(config: str, log: str) -> float:
    session = Session(config)
    for record in read_log(log):
        if isinstance(record.message, Imu):
            reason = session.push("imu", record.message)
            assert reason is None or reason.startswith("duplicate")
    poses: np.ndarray = session.optimized_trajectory()
    return float(ape(poses, poses)["rmse"])
"""


def run_mypy(tmp_path, source):
    path = tmp_path / "usage.py"
    path.write_text(textwrap.dedent(source))
    return subprocess.run([sys.executable, "-m", "mypy", "--no-incremental", "--follow-imports=silent", "--ignore-missing-imports",
                           str(path)], capture_output=True, text=True, cwd=tmp_path)


def test_user_code_type_checks_against_the_stubs(tmp_path):
    import hanzo.fusion
    package = pathlib.Path(hanzo.fusion.__file__).parent
    assert (package / "_fusion.pyi").exists() and (package / "py.typed").exists()
    checked = run_mypy(tmp_path, USAGE)
    assert checked.returncode == 0, checked.stdout
    wrong = run_mypy(tmp_path, USAGE + "\nSession(42)\nX('one')\nPose3.exp(np.zeros(6)).inverse().translation().no_such_attribute\n")
    assert wrong.returncode == 1
    assert 'Argument 1 to "Session" has incompatible type "int"' in wrong.stdout
    assert 'Argument 1 to "X" has incompatible type "str"' in wrong.stdout
    assert '"ndarray[Any, dtype[floating[_64Bit]]]" has no attribute "no_such_attribute"' in wrong.stdout
