"""With HANZO_FUSION_INSTALLED (python/test_installed_package.py), the tests must import the package
pip installed into that environment, never the build tree."""

import os
import pathlib


def pytest_configure(config):
    installed = os.environ.get("HANZO_FUSION_INSTALLED")
    if installed:
        import hanzo.fusion
        location = pathlib.Path(hanzo.fusion.__file__).resolve()
        assert pathlib.Path(installed).resolve() in location.parents, f"hanzo.fusion imported from {location}, not from {installed}"
