"""Builds the Python wheel `actengine`: the C++ core (kernels, weights, graph, engine, the conversion
API) and the extension actengine._actengine, by CMake, for the interpreter that runs this script
(pip's: a venv, conda or the system Python). pyproject.toml holds the metadata; this file only
drives CMake and reads the version.

    pip install .                                   # online, with build isolation
    pip install --no-build-isolation --no-index .   # offline, Debian's setuptools, wheel, pybind11, cmake
    pip wheel --no-build-isolation --no-index -w dist .

Environment: CMAKE_ARGS (extra configure arguments, shell-split, e.g. the ccache launchers or a
toolchain file), CMAKE_BUILD_PARALLEL_LEVEL (jobs; CMake reads it), ACT_PIP_BUILD_DIR (the CMake
build folder, default build-pip-<SOABI>-<interpreter hash>; kept, so a second build is incremental; one level deep
like build/, so ccache with CCACHE_BASEDIR reuses a developer build's objects).
"""

import hashlib
import os
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent


def project_version():
    """The project VERSION in CMakeLists.txt: the one version of the library, the tools and the wheel."""
    text = (ROOT / "CMakeLists.txt").read_text()
    found = re.search(r"project\(\s*actengine\s+VERSION\s+([0-9][0-9.]*)", text)
    if not found:
        raise RuntimeError("no 'project(actengine VERSION x.y.z' in CMakeLists.txt")
    return found.group(1)


class CMakeExtension(Extension):
    def __init__(self, name):
        super().__init__(name, sources=[])


class CMakeBuild(build_ext):
    """Configures the project with only what the module needs (no apps, tests or benchmarks), builds the
    target actengine_python (the extension, and where OpenCV is found the calibration readers) and
    copies it where setuptools puts extensions."""

    def build_extension(self, ext):
        cmake = shutil.which("cmake")
        if cmake is None:
            raise RuntimeError("cmake (3.25 or newer) is needed to build actengine: apt install cmake, or pip install cmake")
        # One folder per interpreter (two Pythons 3.11 share the SOABI, not the headers); venvs of one
        # interpreter share it.
        tag = sysconfig.get_config_var("SOABI") or f"py{sys.version_info[0]}{sys.version_info[1]}"
        tag += "-" + hashlib.sha1(os.path.realpath(sys.executable).encode()).hexdigest()[:8]
        build_dir = Path(os.environ.get("ACT_PIP_BUILD_DIR") or ROOT / f"build-pip-{tag}").resolve()
        build_dir.mkdir(parents=True, exist_ok=True)
        args = [
            f"-S{ROOT}", f"-B{build_dir}",
            "-DCMAKE_BUILD_TYPE=Release",
            "-DACT_BUILD_APPS=OFF", "-DACT_BUILD_TESTS=OFF", "-DACT_BUILD_BENCH=OFF",
            "-DACT_BUILD_PYTHON=ON",
            f"-DPython3_EXECUTABLE={sys.executable}",
        ]
        try:  # pybind11's CMake files: from the pip package (build isolation) or Debian's python3-pybind11
            import pybind11

            args.append(f"-Dpybind11_DIR={pybind11.get_cmake_dir()}")
        except ImportError:
            pass  # pybind11-dev's /usr/lib/cmake/pybind11, found by find_package
        if shutil.which("ninja") and not (build_dir / "CMakeCache.txt").exists():
            args.append("-GNinja")
        args += shlex.split(os.environ.get("CMAKE_ARGS", ""))
        subprocess.run([cmake, *args], check=True)
        build = [cmake, "--build", str(build_dir), "--target", "actengine_python"]
        if "CMAKE_BUILD_PARALLEL_LEVEL" not in os.environ:
            build += ["-j", str(os.cpu_count() or 1)]
        subprocess.run(build, check=True)

        suffix = sysconfig.get_config_var("EXT_SUFFIX")
        built = build_dir / "python" / "actengine" / f"_actengine{suffix}"
        if not built.exists():
            raise RuntimeError(f"CMake built no {built}")
        destination = Path(self.get_ext_fullpath(ext.name))
        destination.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(built, destination)
        # Where OpenCV was found: the calibration readers (actengine._media) and their image and video
        # module, beside the extension (engine/python/media_api.h, engine/media/media_io.h).
        for optional in (f"_media{suffix}", "libact_media_io.so"):
            if (built.parent / optional).exists():
                shutil.copyfile(built.parent / optional, destination.parent / optional)


setup(
    version=project_version(),
    packages=["actengine"],
    package_dir={"actengine": "engine/python/actengine"},
    ext_modules=[CMakeExtension("actengine._actengine")],
    cmdclass={"build_ext": CMakeBuild},
    # setuptools' own scratch folders next to the CMake one, not in build/ (the developers' CMake tree)
    options={"build": {"build_base": "build-pip"}, "egg_info": {"egg_base": "build-pip"}},
    zip_safe=False,
)
