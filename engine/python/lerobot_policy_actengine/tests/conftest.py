"""LeRobot 0.6.2's own code (../shared/tools/lerobot: its unmodified source and the harness that imports
it on Debian's Python 3.11 with torch 1.13) and package folders written by act_convert --package.
Missing data or tools skip a test locally and FAIL it under CI=true."""

import importlib
import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

SHARED = Path(os.environ.get("ACT_SHARED_DIR", Path(__file__).resolve().parents[4] / ".." / "shared"))
CAMERA = "observation.images.front"
STATE = "observation.state"


def require(path, what="test data"):
    if not path or not Path(path).exists():
        if os.environ.get("CI") == "true":
            pytest.fail(f"required {what} missing (CI=true): '{path}'")
        pytest.skip(f"{what} missing: '{path}'")
    return Path(path)


def _stub(name, **attributes):
    module = types.ModuleType(name)
    module.__dict__.update(attributes)
    sys.modules[name] = module
    return module


def _load_lerobot():
    """The harness's namespace plus LeRobot's policy factory (lerobot/policies/factory.py, the module
    that lerobot-record's make_policy and lerobot-rollout's get_policy_class come from).

    factory.py imports, beside what the harness loads, three things that do not matter to a policy
    loaded from a folder and that cannot be imported here: lerobot.envs (gymnasium; make_policy uses it
    only without ds_meta), and three other policies' configs (Evo1, Groot, MolmoAct2: torch 2's
    _dynamo, transformers), which it uses only in isinstance checks. Those are stand-ins; everything
    else is LeRobot's."""
    tools = require(SHARED / "tools" / "lerobot", "LeRobot harness")
    if str(tools) not in sys.path:
        sys.path.insert(0, str(tools))
    from lerobot_harness import loader

    ns = loader.load(os.environ.get("LEROBOT_SRC") or tools / "lerobot-0.6.2")

    class EnvConfig:  # only a type annotation and the env_cfg branch, unused with ds_meta
        pass

    def env_to_policy_features(env_cfg):
        raise NotImplementedError("no gymnasium here: give make_policy a ds_meta")

    _stub("lerobot.envs", EnvConfig=EnvConfig, env_to_policy_features=env_to_policy_features)
    configs = sys.modules["lerobot.configs"]
    config_types = importlib.import_module("lerobot.configs.types")
    for name in dir(config_types):
        if not name.startswith("_") and not hasattr(configs, name):
            setattr(configs, name, getattr(config_types, name))
    processor = sys.modules["lerobot.processor"]
    relative = importlib.import_module("lerobot.processor.relative_action_processor")
    converters = importlib.import_module("lerobot.processor.converters")
    processor.AbsoluteActionsProcessorStep = relative.AbsoluteActionsProcessorStep
    processor.RelativeActionsProcessorStep = relative.RelativeActionsProcessorStep
    for name in ("batch_to_transition", "policy_action_to_transition", "transition_to_batch",
                 "transition_to_policy_action"):
        setattr(processor, name, getattr(converters, name))
    for package, module, cls in [("evo1", "configuration_evo1", "Evo1Config"),
                                 ("groot", "configuration_groot", "GrootConfig"),
                                 ("molmoact2", "configuration_molmoact2", "MolmoAct2Config")]:
        _stub(f"lerobot.policies.{package}")
        _stub(f"lerobot.policies.{package}.{module}", **{cls: type(cls, (), {})})
    ns.factory = importlib.import_module("lerobot.policies.factory")
    # lerobot-rollout's sync inference engine (what --inference.type=sync runs each tick); the two
    # package __init__ files import every strategy, dataset and robot: empty packages instead.
    for name in ("lerobot.rollout", "lerobot.rollout.inference"):
        package = _stub(name)
        package.__path__ = [str(Path(ns.src) / Path(*name.split(".")))]
    ns.sync_inference = importlib.import_module("lerobot.rollout.inference.sync")
    ns.converters = converters
    return ns


@pytest.fixture(scope="session")
def lerobot():
    ns = _load_lerobot()
    ns.register_third_party_plugins()  # LeRobot's discovery of the installed plugin distribution
    return ns


def act_convert(checkpoint, package, *args):
    binary = require(os.environ.get("ACT_CONVERT_BIN"), "act_convert (ACT_CONVERT_BIN)")
    result = subprocess.run([str(binary), str(checkpoint), "--package", str(package), *args],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return package


def patched_checkpoint(source, destination, **config):
    """A copy of a checkpoint folder with config.json fields replaced (weights linked)."""
    destination.mkdir(parents=True, exist_ok=True)
    for entry in source.iterdir():
        if entry.name != "config.json":
            (destination / entry.name).symlink_to(entry)
    patched = json.loads((source / "config.json").read_text())
    patched.update(config)
    (destination / "config.json").write_text(json.dumps(patched, indent=4))
    return destination


@pytest.fixture(scope="session")
def act_tiny():
    return require(SHARED / "fixtures" / "act-tiny")


@pytest.fixture(scope="session")
def ensembling_checkpoint(act_tiny, tmp_path_factory):
    return patched_checkpoint(act_tiny, tmp_path_factory.mktemp("ensembling") / "checkpoint",
                              temporal_ensemble_coeff=0.01, n_action_steps=1)


@pytest.fixture(scope="session")
def fp32_package(act_tiny, tmp_path_factory):
    return act_convert(act_tiny, tmp_path_factory.mktemp("fp32") / "package", "--precision", "fp32")


@pytest.fixture(scope="session")
def ensembling_package(ensembling_checkpoint, tmp_path_factory):
    return act_convert(ensembling_checkpoint, tmp_path_factory.mktemp("fp32-ens") / "package", "--precision", "fp32")


@pytest.fixture(scope="session")
def reference(act_tiny):
    tools = require(SHARED / "tools" / "lerobot", "LeRobot harness")
    if str(tools) not in sys.path:
        sys.path.insert(0, str(tools))
    from lerobot_harness import stio

    return stio.load_file_numpy(str(act_tiny / "reference.safetensors"))


def robot_observations(ticks, seed=0):
    """What a robot's get_observation hands predict_action: HxWx3 uint8 frames, float32 states."""
    rng = np.random.default_rng(seed)
    for _ in range(ticks):
        yield {CAMERA: rng.integers(0, 256, (96, 128, 3), dtype=np.uint8),
               STATE: rng.standard_normal(2).astype(np.float32)}


@pytest.fixture(scope="session")
def int8_package(act_tiny, tmp_path_factory):
    return act_convert(act_tiny, tmp_path_factory.mktemp("int8") / "package", "--precision", "int8", "--mode", "dynamic")


def act_eval_error(blob, observations):
    """act_eval's max |diff| / (1 + |ref|) of a blob's chunks against the reference in `observations`,
    rounded up by half a unit of its last printed digit (it prints three significant digits)."""
    import re
    from decimal import Decimal

    binary = require(os.environ.get("ACT_EVAL_BIN"), "act_eval (ACT_EVAL_BIN)")
    result = subprocess.run([str(binary), "-m", str(blob), "-i", str(observations), "--compare", "-t", "1"],
                            capture_output=True, text=True)
    found = re.search(r"max \|diff\|/\(1\+\|ref\|\) ([0-9.eE+-]+)", result.stdout)
    assert found, result.stdout + result.stderr
    printed = Decimal(found.group(1))
    return float(printed + Decimal(5).scaleb(printed.as_tuple().exponent - 1))
