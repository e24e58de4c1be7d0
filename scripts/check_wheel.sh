#!/usr/bin/env bash
# The pip packaging, end to end, offline: builds the wheel of the checkout (pyproject.toml, setup.py:
# the whole core plus the module; a warm ccache makes it quick) and the LeRobot
# plugin's wheel, then for each Python it checks
#   - Debian's /usr/bin/python3 in a fresh `python3 -m venv --system-site-packages` (numpy from Debian);
#   - pyenv's Python 3.11 (ACT_PYENV_PYTHON) in a plain venv: its own wheel, built by its own pip, with
#     only Debian's dist-packages folder added for numpy (and the build's setuptools/wheel/pybind11);
# that `import actengine` works from outside the source tree, that the module is the one built for
# that interpreter, that actengine.__version__ is CMakeLists.txt's VERSION, that act-tiny converts
# (actengine.convert, FP32, and INT8 calibrated on the fixture's folder of images where the wheel has
# the readers) and runs (Policy.select_action) against the fixture's reference, and (Debian's, which
# has torch) that LeRobot 0.6.2's register_third_party_plugins finds the plugin's policy type.
# Prints the wheels' build times and sizes.
#   check_wheel.sh [debian|pyenv ...]   (default both). CTest runs one each: python_wheel_debian,
# python_wheel_pyenv. Exit 77 (CTest's skip): pyenv's Python missing (a property of the machine),
# or Debian's python3/pip/setuptools/wheel/pybind11 missing outside CI (under CI=true: a failure).
#   ACT_WHEEL_WORK (default /tmp/actengine-wheel-check), ACT_PYENV_PYTHON (default ~/.pyenv/versions/3.11*/bin/python3),
#   ACT_SHARED_DIR (fixtures). Set CMAKE_ARGS for ccache, as setup.py says.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
work="${ACT_WHEEL_WORK:-/tmp/actengine-wheel-check}"
shared="${ACT_SHARED_DIR:-$root/../shared}"
fixture="$shared/fixtures/act-tiny"
version="$(sed -n 's/^project(actengine VERSION \([0-9.]*\).*/\1/p' "$root/CMakeLists.txt")"
[ -n "$version" ] || { echo "check_wheel: no project VERSION in CMakeLists.txt" >&2; exit 1; }
[ -d "$fixture" ] || { echo "check_wheel: fixture missing: $fixture" >&2; exit 1; }
pyenv_python="${ACT_PYENV_PYTHON:-$(ls -d "$HOME"/.pyenv/versions/3.11*/bin/python3 2>/dev/null | tail -n 1)}"
which_pythons=("$@")
[ ${#which_pythons[@]} -gt 0 ] || which_pythons=(debian pyenv)
if ! { /usr/bin/python3 -c 'import setuptools, wheel, pybind11, venv' && /usr/bin/python3 -m pip --version; } >/dev/null 2>&1; then
  echo "check_wheel: Debian's python3 with pip, setuptools, wheel, pybind11 and venv is needed (scripts/install_deps.sh)" >&2
  [ "${CI:-}" = true ] && exit 1
  exit 77
fi
rm -rf "$work"; mkdir -p "$work"
pip_offline=(install -q --no-index --no-deps --no-build-isolation --disable-pip-version-check)

# One interpreter: venv, wheel built by that venv's pip, installed, checked from $work (not the tree).
check() {
  local name="$1" base="$2" venv_flags="$3"
  local venv="$work/venv-$name" dist="$work/dist-$name"
  echo "== $name: $("$base" --version) ($base)"
  "$base" -m venv $venv_flags "$venv"
  if [ -z "$venv_flags" ]; then  # no system site: Debian's dist-packages for numpy, pybind11, setuptools' wheel
    echo /usr/lib/python3/dist-packages >"$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/debian-dist-packages.pth"
  fi
  local start=$SECONDS
  # A fresh CMake folder, one level under the checkout like build/ (so ccache with CCACHE_BASEDIR set
  # reuses a developer build's objects).
  local cmake_dir="$root/build-wheel-check-$name"
  rm -rf "$cmake_dir"
  (cd "$root" && ACT_PIP_BUILD_DIR="$cmake_dir" "$venv/bin/python" -m pip wheel -q --no-index --no-deps \
     --no-build-isolation --disable-pip-version-check -w "$dist" .)
  echo "wheel     $(basename "$dist"/actengine-*.whl): $((SECONDS - start)) s, $(du -k "$dist"/actengine-*.whl | cut -f1) KiB"
  local built_for
  built_for="$(sed -n 's/^Python3_EXECUTABLE:[A-Z]*=//p' "$cmake_dir/CMakeCache.txt")"
  echo "built for $built_for, headers $(sed -n 's/^_Python3_INCLUDE_DIR:INTERNAL=//p' "$cmake_dir/CMakeCache.txt")"
  [ "$built_for" = "$venv/bin/python" ] || { echo "check_wheel: the module was built for $built_for, not $venv/bin/python" >&2; exit 1; }
  "$venv/bin/python" -m pip "${pip_offline[@]}" "$dist"/actengine-*.whl
  "$venv/bin/python" -m pip "${pip_offline[@]}" "$root/engine/python/lerobot_policy_actengine"
  (cd "$work" && ACT_FIXTURE="$fixture" ACT_VERSION="$version" ACT_VENV="$venv" ACT_NAME="$name" "$venv/bin/python" - <<'PY'
import importlib.metadata, importlib.util, os, sys, sysconfig
from pathlib import Path
import numpy as np
import actengine
from actengine import _actengine

venv = Path(os.environ["ACT_VENV"]).resolve()
assert Path(actengine.__file__).resolve().is_relative_to(venv), actengine.__file__  # the installed copy
assert _actengine.__file__.endswith(sysconfig.get_config_var("EXT_SUFFIX")), _actengine.__file__
assert actengine.__version__ == os.environ["ACT_VERSION"] == importlib.metadata.version("actengine"), actengine.__version__
assert importlib.metadata.version("lerobot_policy_actengine") == actengine.__version__
fixture = Path(os.environ["ACT_FIXTURE"])
blob = Path("act-tiny.actb").resolve()
actengine.convert(fixture, blob, "fp32")
sys.path.insert(0, str(fixture.parents[1] / "tools" / "lerobot"))
from lerobot_harness import stio
ref = stio.load_file_numpy(str(fixture / "reference.safetensors"))
policy = actengine.Policy(actengine.Engine(blob, threads=1))
observation = {"observation.images.front": ref["input.observation.images.front.u8_nhwc"][0],
               "observation.state": ref["input.observation.state"][0]}
actions = np.array([policy.select_action(observation) for _ in range(10)])
np.testing.assert_allclose(actions, ref["select_action.queue_sample0"], rtol=1e-4, atol=1e-4)
print(f"checked   actengine {actengine.__version__} on Python {sys.version.split()[0]}: import, convert, "
      f"10 actions of act-tiny match LeRobot (max |diff| {np.abs(actions - ref['select_action.queue_sample0']).max():.1e})")
if importlib.util.find_spec("actengine._media"):  # the calibration readers, where OpenCV was found
    report = actengine.convert(fixture, "int8.actb", calib=fixture, calib_samples=3, holdout=1)["report"]
    assert report["notes"][0] == "4 frames given, 3 used for calibration, 1 held out", report["notes"]
    print("checked   convert(calib=folder): 4 frames read by the wheel's readers")
else:
    assert os.environ["ACT_NAME"] != "debian", "the wheel has no actengine._media (built without OpenCV?)"
if os.environ["ACT_NAME"] == "debian":  # LeRobot's discovery, on Debian's torch
    from lerobot_harness import loader
    lerobot = loader.load(fixture.parents[1] / "tools" / "lerobot" / "lerobot-0.6.2")
    lerobot.register_third_party_plugins()
    assert "lerobot_policy_actengine" in sys.modules, "register_third_party_plugins did not import the plugin"
    assert lerobot.PreTrainedConfig.get_choice_class("actengine").__name__ == "ActengineConfig"
    print("checked   LeRobot's register_third_party_plugins found the policy type 'actengine'")
PY
  )
}

skipped=0
for which in "${which_pythons[@]}"; do
  case "$which" in
    debian) check debian /usr/bin/python3 --system-site-packages ;;
    pyenv)
      if [ -n "$pyenv_python" ] && [ -x "$pyenv_python" ]; then
        check pyenv "$pyenv_python" ""
      else  # the machine's, not the project's: a skip, under CI too
        echo "check_wheel: skipped pyenv: no pyenv Python 3.11 here (~/.pyenv/versions/3.11*/bin/python3; ACT_PYENV_PYTHON picks one)" >&2
        skipped=1
      fi ;;
    *) echo "check_wheel: unknown interpreter '$which' (debian or pyenv)" >&2; exit 2 ;;
  esac
done
[ "$skipped" = 0 ] || [ ${#which_pythons[@]} -gt 1 ] || exit 77
echo "check_wheel: OK"
