"""Builds the wheel of hanzo.fusion (pyproject.toml): the extension hanzo.fusion._fusion, its type
stubs and the generated hanzo.fusion.v1 modules come from the project's CMake build (target
hanzo_fusion_python_package); setuptools adds the pure-Python modules of python/hanzo.

The CMake build lives in build/python-package (the library without server, programs, tests and
benchmarks); HANZO_FUSION_BUILD_DIR names another, e.g. the `make build` tree, to reuse what it
built. HANZO_FUSION_BUILD_JOBS caps the parallel compile jobs (default: the CPU count).
"""

import os
import pathlib
import re
import shutil
import subprocess
import sys
import sysconfig

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = pathlib.Path(__file__).resolve().parent


def project_version():
    match = re.search(r"project\(hanzo_fusion VERSION ([0-9.]+)", (ROOT / "CMakeLists.txt").read_text())
    if not match:
        raise RuntimeError("CMakeLists.txt: no project(hanzo_fusion VERSION ...) found")
    return match.group(1)


class CMakeBuild(build_ext):
    """Runs CMake for the one extension, then copies what the CMake build assembled."""

    def build_extension(self, ext):
        build_dir = pathlib.Path(os.environ.get("HANZO_FUSION_BUILD_DIR") or ROOT / "build" / "python-package").resolve()
        if not (build_dir / "CMakeCache.txt").exists():
            self.spawn(["cmake", "-S", str(ROOT), "-B", str(build_dir), "-G", "Ninja", "-DCMAKE_BUILD_TYPE=Release",
                        f"-DPython_EXECUTABLE={sys.executable}", "-DHANZO_BUILD_TESTS=OFF", "-DHANZO_BUILD_BENCHMARKS=OFF",
                        "-DHANZO_BUILD_APPS=OFF", "-DHANZO_BUILD_SERVICE=OFF"])
        jobs = os.environ.get("HANZO_FUSION_BUILD_JOBS") or str(os.cpu_count() or 1)
        self.spawn(["cmake", "--build", str(build_dir), "--target", "hanzo_fusion_python_package", "-j", jobs])

        built = build_dir / "python" / "hanzo" / "fusion"
        suffix = sysconfig.get_config_var("EXT_SUFFIX")
        extension = built / f"_fusion{suffix}"
        if not extension.exists():
            found = ", ".join(p.name for p in built.glob("_fusion*.so")) or "none"
            raise RuntimeError(f"{extension} was not built (found: {found}): the CMake build in {build_dir} is for another "
                               f"Python than {sys.executable}; remove it or point HANZO_FUSION_BUILD_DIR elsewhere")
        target = pathlib.Path(self.get_ext_fullpath(ext.name)).parent
        (target / "v1").mkdir(parents=True, exist_ok=True)
        shutil.copy2(extension, self.get_ext_fullpath(ext.name))
        shutil.copy2(built / "_fusion.pyi", target / "_fusion.pyi")
        for generated in (built / "v1").iterdir():
            if generated.suffix in (".py", ".pyi"):
                shutil.copy2(generated, target / "v1" / generated.name)


setup(
    version=project_version(),
    ext_modules=[Extension("hanzo.fusion._fusion", sources=[])],
    cmdclass={"build_ext": CMakeBuild},
    options={"build": {"build_base": str(pathlib.Path("build") / "python-wheel")}},
)
