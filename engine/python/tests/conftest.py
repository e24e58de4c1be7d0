"""Shared test data for the actengine module's tests: LeRobot's fixtures from ../shared (or
$ACT_SHARED_DIR), their references, and FP32 blobs converted once per session. Missing data skips a
test locally and FAILS it under CI=true, as the C++ tests do (test/support/test_paths.h)."""

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

import actengine

SHARED = Path(os.environ.get("ACT_SHARED_DIR", Path(__file__).resolve().parents[3] / ".." / "shared"))
FIXTURES = ["act-tiny", "act-tiny-legacy"]
CAMERA = "observation.images.front"
STATE = "observation.state"


def require(path):
    """`path`, or a skip (a failure under CI=true) when it does not exist."""
    if not Path(path).exists():
        message = f"test data missing: '{path}'"
        if os.environ.get("CI") == "true":
            pytest.fail(f"required test data missing (CI=true): '{path}'")
        pytest.skip(message)
    return Path(path)


def load_reference(fixture_dir):
    """The fixture's reference.safetensors as numpy arrays (the shared harness's reader)."""
    tools = require(SHARED / "tools" / "act_reference")
    if str(tools) not in sys.path:
        sys.path.insert(0, str(tools))
    from act_harness import stio

    return stio.load_file_numpy(str(fixture_dir / "reference.safetensors"))


class Fixture:
    """One LeRobot fixture: its folder, reference tensors and LeRobot-shaped observations."""

    def __init__(self, name, directory):
        self.name = name
        self.dir = directory
        self.ref = load_reference(directory)
        self.samples = self.ref["input.observation.state"].shape[0]

    def observation(self, i):
        """Sample i as the robot loop has it: HxWx3 uint8 frame, batch-less float32 state."""
        return {
            CAMERA: self.ref["input.observation.images.front.u8_nhwc"][i],
            STATE: self.ref["input.observation.state"][i].astype(np.float32),
        }


@pytest.fixture(scope="session", params=FIXTURES)
def fixture(request):
    return Fixture(request.param, require(SHARED / "fixtures" / request.param))


@pytest.fixture(scope="session")
def act_tiny():
    return Fixture("act-tiny", require(SHARED / "fixtures" / "act-tiny"))


@pytest.fixture(scope="session")
def fp32_blob(fixture, tmp_path_factory):
    blob = tmp_path_factory.mktemp(fixture.name) / "model.actb"
    actengine.convert(fixture.dir, blob, "fp32")
    return blob


@pytest.fixture(scope="session")
def tiny_blob(act_tiny, tmp_path_factory):
    blob = tmp_path_factory.mktemp("act-tiny-fp32") / "model.actb"
    actengine.convert(act_tiny.dir, blob, "fp32")
    return blob


@pytest.fixture(scope="session")
def tiny_engine(tiny_blob):
    return actengine.Engine(tiny_blob, threads=1)


def patched_checkpoint(fixture, destination, **config):
    """A copy of the fixture's checkpoint folder with config.json fields replaced."""
    destination.mkdir(parents=True, exist_ok=True)
    for entry in fixture.dir.iterdir():
        if entry.name != "config.json":
            (destination / entry.name).symlink_to(entry)
    patched = json.loads((fixture.dir / "config.json").read_text())
    patched.update(config)
    (destination / "config.json").write_text(json.dumps(patched, indent=4))
    return destination
