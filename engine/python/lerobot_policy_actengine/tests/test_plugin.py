"""The plugin through LeRobot 0.6.2's own code: discovery (register_third_party_plugins), the config
registry, the factory's policy-class convention, make_policy (lerobot-record / lerobot-eval),
from_pretrained as lerobot-rollout calls it, make_pre_post_processors, and predict_action (the per
tick path of lerobot-rollout's sync engine): actions against LeRobot's own ACTPolicy on the same
checkpoint and against the fixture's reference."""

import json
import shutil
import struct

import numpy as np
import pytest
import torch

from conftest import CAMERA, STATE, robot_observations

TICKS = 250
CPU = torch.device("cpu")
ROLLOUT_OVERRIDES = {"device_processor": {"device": "cpu"}, "rename_observations_processor": {"rename_map": {}}}


class DatasetMeta:
    """What make_policy reads of LeRobotDatasetMetadata (lerobot-record's dataset of the robot)."""

    def __init__(self, cameras=None, state=2, action=2):
        self.features = {STATE: {"dtype": "float32", "shape": (state,), "names": None},
                         "action": {"dtype": "float32", "shape": (action,), "names": None}}
        for key, (h, w) in (cameras or {CAMERA: (96, 128)}).items():
            self.features[key] = {"dtype": "video", "shape": (h, w, 3), "names": ["height", "width", "channels"]}
        self.stats = {}


def load_like_rollout(lerobot, folder):
    """lerobot-rollout: config from --policy.path, the class by the factory's convention, its
    from_pretrained, and the folder's processors with rollout's overrides."""
    cfg = lerobot.PreTrainedConfig.from_pretrained(folder, revision=None, cli_overrides=[])
    cfg.pretrained_path = folder
    policy = lerobot.factory.get_policy_class(cfg.type).from_pretrained(cfg.pretrained_path, config=cfg, revision=None)
    pre, post = lerobot.factory.make_pre_post_processors(policy_cfg=cfg, pretrained_path=str(folder), pretrained_revision=None,
                                                         dataset_stats=None, preprocessor_overrides=ROLLOUT_OVERRIDES)
    return policy, pre, post


def load_lerobot_act(lerobot, checkpoint):
    """LeRobot's own ACTPolicy and the checkpoint's processors (the harness README's recipe)."""
    cfg = lerobot.PreTrainedConfig.from_pretrained(checkpoint)
    cfg.pretrained_backbone_weights = None  # every weight is in model.safetensors
    policy = lerobot.ACTPolicy.from_pretrained(checkpoint, config=cfg)
    pre, post = lerobot.factory.make_pre_post_processors(policy_cfg=cfg, pretrained_path=str(checkpoint))
    return policy, pre, post


def run(lerobot, loaded, observations):
    policy, pre, post = loaded
    policy.reset()
    return np.stack([lerobot.predict_action(dict(o), policy, CPU, pre, post, use_amp=False, task=None,
                                            robot_type=None).numpy() for o in observations])


def test_plugin_is_discovered_and_registered(lerobot):
    import importlib.metadata

    names = [d.metadata["Name"] for d in importlib.metadata.distributions()]
    assert "lerobot_policy_actengine" in names  # LeRobot compares this literally with "lerobot_policy_"
    assert "actengine" in lerobot.PreTrainedConfig.get_known_choices()
    cls = lerobot.factory.get_policy_class("actengine")
    assert cls.__name__ == "ActenginePolicy" and issubclass(cls, lerobot.PreTrainedPolicy)


def test_folder_config_has_the_checkpoints_features(lerobot, act_tiny, fp32_package):
    ours = lerobot.PreTrainedConfig.from_pretrained(fp32_package)
    theirs = lerobot.PreTrainedConfig.from_pretrained(act_tiny)
    assert ours.type == "actengine" and theirs.type == "act"
    assert ours.input_features == theirs.input_features and ours.output_features == theirs.output_features
    assert (ours.chunk_size, ours.n_action_steps, ours.temporal_ensemble_coeff) == (10, 10, None)
    assert ours.normalization == "blob"


@pytest.mark.parametrize("mode", ["queue", "temporal_ensembling"])
def test_predict_action_matches_lerobot_act(lerobot, act_tiny, ensembling_checkpoint, fp32_package, ensembling_package,
                                            mode):
    checkpoint, package = (act_tiny, fp32_package) if mode == "queue" else (ensembling_checkpoint, ensembling_package)
    observations = list(robot_observations(TICKS))
    ours = run(lerobot, load_like_rollout(lerobot, package), observations)
    theirs = run(lerobot, load_lerobot_act(lerobot, checkpoint), observations)
    assert ours.shape == theirs.shape == (TICKS, 1, 2) and ours.dtype == np.float32
    error = np.abs(ours - theirs) / (1 + np.abs(theirs))
    assert error.max() <= 1e-4, f"{mode}: worst tick {int(error.argmax()) // 2}, relative error {error.max():.2e}"
    assert np.abs(theirs).max() > 0.1  # the comparison is about real actions


def test_make_policy_as_record_and_eval_call_it(lerobot, reference, fp32_package):
    """make_policy with the robot's dataset features, then the queue: the reference's 10 actions."""
    cfg = lerobot.PreTrainedConfig.from_pretrained(fp32_package)
    cfg.pretrained_path = fp32_package
    policy = lerobot.factory.make_policy(cfg, ds_meta=DatasetMeta())
    pre, post = lerobot.factory.make_pre_post_processors(cfg, pretrained_path=str(fp32_package))
    frame = {CAMERA: reference["input.observation.images.front.u8_nhwc"][0],
             STATE: reference["input.observation.state"][0]}
    expected = reference["select_action.queue_sample0"]
    for episode in range(2):  # reset() starts the queue over
        actions = run(lerobot, (policy, pre, post), [frame] * len(expected))[:, 0]
        np.testing.assert_allclose(actions, expected, rtol=1e-4, atol=1e-4, err_msg=f"episode {episode}")
    chunk = policy.predict_action_chunk(pre(lerobot.policy_utils.prepare_observation_for_inference(dict(frame), CPU)))
    assert tuple(chunk.shape) == (1, 10, 2)
    np.testing.assert_allclose(chunk[0].numpy(), reference["output.action"][0], rtol=1e-4, atol=1e-4)


def test_processors_do_not_normalise(lerobot, fp32_package):
    _, pre, post = load_like_rollout(lerobot, fp32_package)
    names = [type(step).__name__ for step in pre.steps + post.steps]
    assert not [n for n in names if "ormalizer" in n], names


def copy_package(package, destination):
    shutil.copytree(package, destination)
    return destination


def test_folder_without_blob(lerobot, fp32_package, tmp_path):
    folder = copy_package(fp32_package, tmp_path / "package")
    (folder / "model.actb").unlink()
    with pytest.raises(FileNotFoundError, match="no blob 'model.actb'.*act_convert"):
        load_like_rollout(lerobot, folder)


def test_blob_of_a_newer_format(lerobot, fp32_package, tmp_path):
    folder = copy_package(fp32_package, tmp_path / "package")
    blob = bytearray((folder / "model.actb").read_bytes())
    (version,) = struct.unpack_from("<I", blob, 8)  # the header's format version (weights/blob/actb.h)
    struct.pack_into("<I", blob, 8, version + 1)
    (folder / "model.actb").write_bytes(bytes(blob))
    with pytest.raises(RuntimeError, match=f"format version {version + 1}.*newer actengine"):
        load_like_rollout(lerobot, folder)


def edited_config(package, destination, edit):
    folder = copy_package(package, destination)
    config = json.loads((folder / "config.json").read_text())
    edit(config)
    (folder / "config.json").write_text(json.dumps(config))
    return folder


def test_features_that_do_not_match_the_blob(lerobot, fp32_package, tmp_path):
    def rename_camera(config):
        config["input_features"]["observation.images.wrist"] = config["input_features"].pop(CAMERA)

    def resize_state(config):
        config["input_features"][STATE]["shape"] = [3]

    for name, edit, message in [("camera", rename_camera, r"cameras: the blob takes \['observation.images.front'\]"),
                                ("state", resize_state, r"observation.state: the blob takes \(2,\)")]:
        folder = edited_config(fp32_package, tmp_path / name, edit)
        with pytest.raises(ValueError, match=message):
            load_like_rollout(lerobot, folder)


def test_robot_whose_features_do_not_match(lerobot, fp32_package):
    """make_policy puts the dataset's action feature in the config: a 3-joint robot is refused."""
    cfg = lerobot.PreTrainedConfig.from_pretrained(fp32_package)
    cfg.pretrained_path = fp32_package
    with pytest.raises(ValueError, match=r"action: the blob takes \(2,\)"):
        lerobot.factory.make_policy(cfg, ds_meta=DatasetMeta(action=3))
    cfg = lerobot.PreTrainedConfig.from_pretrained(fp32_package)
    cfg.pretrained_path = fp32_package
    with pytest.raises(ValueError):  # LeRobot's own visual-feature check (validate_visual_features_consistency)
        lerobot.factory.make_policy(cfg, ds_meta=DatasetMeta(cameras={"observation.images.wrist": (96, 128)}))


def test_processors_that_normalise_again(lerobot, act_tiny, fp32_package, tmp_path):
    folder = copy_package(fp32_package, tmp_path / "package")
    for name in act_tiny.glob("policy_preprocessor*"):
        shutil.copy(name, folder / name.name)  # LeRobot ACT's processors: they normalise
    with pytest.raises(ValueError, match="normalised twice"):
        load_like_rollout(lerobot, folder)


def test_python_writer_gives_act_converts_files(lerobot, act_tiny, ensembling_checkpoint, fp32_package, ensembling_package,
                                                tmp_path):
    """actengine-package (pip only, no act_convert) writes act_convert --package's LeRobot files."""
    from lerobot_policy_actengine import package

    for name, checkpoint, expected in [("queue", act_tiny, fp32_package), ("ensembling", ensembling_checkpoint, ensembling_package)]:
        folder = tmp_path / name
        package.main([str(checkpoint), str(folder), "--precision", "fp32"])
        for file in ("config.json", "policy_preprocessor.json", "policy_postprocessor.json"):
            assert json.loads((folder / file).read_text()) == json.loads((expected / file).read_text()), f"{name}: {file}"
    cfg = lerobot.PreTrainedConfig.from_pretrained(tmp_path / "ensembling")
    assert (cfg.n_action_steps, cfg.temporal_ensemble_coeff) == (1, 0.01)


def test_console_script_is_installed():
    import importlib.metadata

    scripts = {e.name: e.value for e in importlib.metadata.entry_points(group="console_scripts")}
    assert scripts.get("actengine-package") == "lerobot_policy_actengine.package:main"


def test_int8_predict_action_within_act_evals_error(lerobot, act_tiny, reference, int8_package):
    """INT8 (dynamic) through the plugin against LeRobot's ACTPolicy, 250 ticks with the queue, each chunk
    inferred on one of the fixture's observations: within the error act_eval reports for that blob on
    those observations (its chunks against LeRobot's reference)."""
    from conftest import act_eval_error

    bound = act_eval_error(int8_package / "model.actb", act_tiny / "reference.safetensors")
    samples = [{CAMERA: reference["input.observation.images.front.u8_nhwc"][i], STATE: reference["input.observation.state"][i]}
               for i in range(reference["input.observation.state"].shape[0])]
    observations = [samples[(tick // 10) % len(samples)] for tick in range(TICKS)]  # n_action_steps 10
    ours = run(lerobot, load_like_rollout(lerobot, int8_package), observations)
    theirs = run(lerobot, load_lerobot_act(lerobot, act_tiny), observations)
    error = (np.abs(ours - theirs) / (1 + np.abs(theirs))).max()
    assert 0 < error <= bound, f"INT8 error {error:.4g}, act_eval reports {bound:.4g}"


@pytest.mark.parametrize("mode", ["queue", "temporal_ensembling"])
def test_rollout_sync_inference_engine_matches_lerobot_act(lerobot, act_tiny, ensembling_checkpoint, fp32_package,
                                                          ensembling_package, mode):
    """lerobot-rollout's SyncInferenceEngine (reset, get_action per tick, a task change that drops the
    queued actions) with the plugin and with LeRobot's ACTPolicy: the same robot actions."""
    checkpoint, package = (act_tiny, fp32_package) if mode == "queue" else (ensembling_checkpoint, ensembling_package)
    features = {"action": {"dtype": "float32", "shape": (2,), "names": ["steer", "throttle"]}}
    observations = list(robot_observations(TICKS, seed=1))
    results = []
    for policy, pre, post in (load_like_rollout(lerobot, package), load_lerobot_act(lerobot, checkpoint)):
        engine = lerobot.sync_inference.SyncInferenceEngine(policy, pre, post, features, ["steer", "throttle"],
                                                            task="drive", device="cpu", robot_type="rover")
        engine.reset()
        actions = []
        for tick, observation in enumerate(observations):
            if tick == 95:  # mid-chunk: the next tick infers again
                assert engine.set_task("park")
            actions.append(engine.get_action(dict(observation)).numpy())
        results.append(np.array(actions))
    ours, theirs = results
    assert ours.shape == theirs.shape == (TICKS, 2)
    error = np.abs(ours - theirs) / (1 + np.abs(theirs))
    assert error.max() <= 1e-4, f"{mode}: worst tick {int(error.argmax()) // 2}, relative error {error.max():.2e}"
