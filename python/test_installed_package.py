"""Installs hanzo.fusion with pip into a new virtual environment and runs python/tests there,
against the installed package (not the build tree): what `make test` runs as python.pytest.

    /usr/bin/python3 python/test_installed_package.py --build-dir build [pytest arguments...]

The environment sees the system's site-packages (numpy, pytest, grpcio and mypy from Debian: no
package index is reachable offline); pip builds the wheel with --no-build-isolation, reusing the
CMake build in --build-dir (HANZO_FUSION_BUILD_DIR).
"""

import argparse
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile

REPO = pathlib.Path(__file__).resolve().parents[1]

parser = argparse.ArgumentParser()
parser.add_argument("--build-dir", required=True, type=pathlib.Path)
arguments, pytest_arguments = parser.parse_known_args()
build_dir = arguments.build_dir.resolve()
venv = build_dir / "python-venv"
shutil.rmtree(venv, ignore_errors=True)
subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
python = str(venv / "bin" / "python")
environment = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"}
environment["HANZO_FUSION_BUILD_DIR"] = str(build_dir)
subprocess.run([python, "-m", "pip", "install", "--quiet", "--no-build-isolation", "--no-index", str(REPO)], check=True, env=environment)
environment["HANZO_FUSION_INSTALLED"] = str(venv)
with tempfile.TemporaryDirectory() as outside:  # nothing of the checkout on sys.path
    result = subprocess.run([python, "-m", "pytest", "-q", "-p", "no:cacheprovider", *pytest_arguments, str(REPO / "python" / "tests")],
                            cwd=outside, env=environment)
sys.exit(result.returncode)
