"""Runs this folder's pytest suite the way a LeRobot user has the plugin: installed by pip into a
venv (python3 -m venv --system-site-packages, so numpy and torch come from Debian), found by
LeRobot's register_third_party_plugins through the venv's distribution metadata.

    python3 run_in_venv.py VENV_DIR [pytest arguments...]

actengine itself comes from PYTHONPATH (the CMake build tree's build/python): building the wheel
compiles the whole core again, which scripts/check_wheel.sh does (CTest python_wheel_debian, python_wheel_pyenv).
"""

import os
import subprocess
import sys
import venv
from pathlib import Path

HERE = Path(__file__).resolve().parent
PLUGIN = HERE.parent


def main():
    target = Path(sys.argv[1])
    python = target / "bin" / "python"
    if not python.exists():
        venv.EnvBuilder(system_site_packages=True, with_pip=False, clear=True).create(target)
    # Debian's pip (system site) installs into the venv it runs in; offline, no build isolation.
    subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-index", "--no-deps", "--no-build-isolation",
                    "--force-reinstall", "--disable-pip-version-check", str(PLUGIN)], check=True)
    os.execv(str(python), [str(python), "-m", "pytest", *sys.argv[2:], str(HERE)])


if __name__ == "__main__":
    main()
