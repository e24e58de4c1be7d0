"""ActenginePolicy: LeRobot's PreTrainedPolicy over an actengine .actb blob.

select_action, predict_action_chunk and reset keep LeRobot ACT's semantics: the n_action_steps
queue or temporal ensembling (actengine.Policy does both, as actengine's C++ Policy), one action of
shape (1, action_dim) per call. The blob normalises the observation and un-normalises the actions,
so the folder's processors (written by act_convert --package) hold no normaliser: normalisation
happens once. Input: the batch that LeRobot's preprocessor hands over (float32 images
(1, 3, H, W) in [0, 1], float32 states (1, D)); extra keys (task, robot_type, ...) are ignored.
"""

import json
import os
from pathlib import Path

import numpy as np
import torch

import actengine
from actengine.lerobot import model_input_keys
from lerobot.configs.types import FeatureType
from lerobot.policies.pretrained import PreTrainedPolicy

from .configuration_actengine import NORMALIZATION_IN_BLOB, ActengineConfig

STATE_KEY = "observation.state"
PROCESSOR_FILES = ("policy_preprocessor.json", "policy_postprocessor.json")
NORMALIZING_STEPS = ("normalizer_processor", "unnormalizer_processor")


class ActenginePolicy(PreTrainedPolicy):
    config_class = ActengineConfig
    name = "actengine"

    def __init__(self, config: ActengineConfig, dataset_stats=None, dataset_meta=None, **kwargs):
        """Opens the blob of config.pretrained_path (LeRobot sets it from --policy.path); dataset_stats
        and dataset_meta, which make_policy passes, are not used (the blob holds the statistics)."""
        del dataset_stats, dataset_meta, kwargs
        super().__init__(config)
        config.validate_features()
        self.engine = None
        self._policy = None
        if config.pretrained_path is not None:
            self._open(Path(config.pretrained_path))

    @classmethod
    def from_pretrained(cls, pretrained_name_or_path, *, config=None, **kwargs):
        """A folder written by act_convert --package (a local path: the blob is not on the Hub)."""
        folder = Path(pretrained_name_or_path)
        if not folder.is_dir():
            raise FileNotFoundError(f"actengine policy: '{folder}' is not a folder (give --policy.path the folder "
                                    "that act_convert --package wrote)")
        if config is None:
            config = ActengineConfig.from_pretrained(folder)
        config.pretrained_path = folder
        keep = {k: v for k, v in kwargs.items() if k in ("dataset_stats", "dataset_meta")}
        policy = cls(config, **keep)
        policy.eval()
        return policy

    def _open(self, folder: Path):
        blob = folder / self.config.blob
        if not blob.is_file():
            raise FileNotFoundError(f"actengine policy: no blob '{self.config.blob}' in '{folder}' (write the folder with "
                                    "act_convert CHECKPOINT --package FOLDER)")
        check_processors(folder)
        try:
            self.engine = actengine.Engine(blob, threads=self.config.threads, isa=self.config.isa)
        except actengine.Error as error:
            raise RuntimeError(f"actengine {actengine.__version__} cannot open '{blob}': {error} (a blob from a newer "
                               "act_convert needs a newer actengine: pip install --upgrade actengine)") from error
        check_features(self.config, self.engine.model_info, blob)
        self._policy = actengine.Policy(self.engine)
        self._input_keys = model_input_keys(self.engine.model_info)

    def _require_engine(self):
        if self._policy is None:
            raise RuntimeError("actengine policy has no blob: load it with --policy.path FOLDER (act_convert --package "
                               "FOLDER), from_pretrained(FOLDER) or a config whose pretrained_path is that folder")

    def _inputs(self, batch):
        inputs = {}
        for key in self._input_keys:
            if key not in batch:
                raise ValueError(f"actengine policy: the observation has no '{key}' (it has {sorted(batch)})")
            value = batch[key]
            if isinstance(value, torch.Tensor):
                value = value.detach().to("cpu", torch.float32).contiguous().numpy()
            inputs[key] = value
        return inputs

    def get_optim_params(self) -> dict:
        raise NotImplementedError("an actengine policy runs a converted blob: it cannot be trained")

    def reset(self):
        """Empties the action queue / the temporal ensemble (the start of an episode)."""
        if self._policy is not None:
            self._policy.reset()

    def drop_queued_actions(self) -> None:
        """The next select_action runs the network (lerobot-rollout calls it when the task changes):
        empties the action queue. With temporal ensembling every call runs the network anyway, and
        LeRobot's ACT keeps its ensemble then (it clears only its _action_queue): so does this."""
        if self._policy is not None and self.config.temporal_ensemble_coeff is None:
            self._policy.reset()

    @torch.no_grad()
    def select_action(self, batch, **kwargs) -> torch.Tensor:
        """One action, shape (1, action_dim), float32, raw (the blob un-normalises)."""
        del kwargs
        self._require_engine()
        action = self._policy.select_action(self._inputs(batch))
        return torch.from_numpy(np.ascontiguousarray(action)[np.newaxis])

    @torch.no_grad()
    def predict_action_chunk(self, batch, **kwargs) -> torch.Tensor:
        """The whole chunk, shape (1, chunk_size, action_dim), raw actions; the queue is left alone."""
        del kwargs
        self._require_engine()
        chunk = self.engine.infer(self._inputs(batch))
        return torch.from_numpy(np.ascontiguousarray(chunk)[np.newaxis])

    def forward(self, batch):
        raise NotImplementedError("an actengine policy runs a converted blob: it has no training forward pass")


def check_processors(folder: Path):
    """Normalisation happens once: in the blob, so the folder's processors must not normalise too."""
    for name in PROCESSOR_FILES:
        path = folder / name
        if not path.is_file():
            continue  # make_pre_post_processors reports a missing file itself
        steps = json.loads(path.read_text()).get("steps", [])
        found = [s.get("registry_name") for s in steps if s.get("registry_name") in NORMALIZING_STEPS]
        if found:
            raise ValueError(f"actengine policy: '{path}' has {found[0]}, but the blob normalises "
                             f"(normalization '{NORMALIZATION_IN_BLOB}'): actions would be normalised twice. Use the "
                             "processor files act_convert --package wrote")


def _shape(feature):
    return tuple(int(v) for v in feature.shape)


def check_features(config: ActengineConfig, info, blob):
    """The config's (the checkpoint's, or the robot's/dataset's as make_policy sets them) features against
    what the blob takes: cameras and their sizes, state, environment state, action."""
    where = f"'{blob}'"
    problems = []
    inputs = config.input_features or {}
    visual = {k: _shape(ft) for k, ft in inputs.items() if ft.type is FeatureType.VISUAL}
    blob_cameras = {c.key: (3, c.height, c.width) for c in info.cameras}
    if set(visual) != set(blob_cameras):
        problems.append(f"cameras: the blob takes {sorted(blob_cameras)}, the features give {sorted(visual)}")
    else:
        for key, shape in visual.items():
            if shape != blob_cameras[key]:
                problems.append(f"camera '{key}': the blob takes {blob_cameras[key]}, the features give {shape}")

    def check_vector(kind, key, blob_dim, features):
        found = [(k, ft) for k, ft in features.items() if ft.type is kind]
        dims = {k: _shape(ft) for k, ft in found}
        if blob_dim == 0 and not found:
            return
        if blob_dim and key in dims and dims[key] == (blob_dim,) and len(found) == 1:
            return
        problems.append(f"{key}: the blob takes ({blob_dim},), the features give {dims or 'none'}")

    check_vector(FeatureType.STATE, STATE_KEY, info.state_dim, inputs)
    check_vector(FeatureType.ENV, info.env_state_key or "observation.environment_state", info.env_state_dim, inputs)
    check_vector(FeatureType.ACTION, "action", info.action_dim, config.output_features or {})
    if config.chunk_size != info.chunk_size or config.n_action_steps != info.n_action_steps:
        problems.append(f"chunk_size / n_action_steps: the blob has {info.chunk_size} / {info.n_action_steps}, the config "
                        f"{config.chunk_size} / {config.n_action_steps} (act_convert sets them at conversion)")
    coeff = info.temporal_ensemble_coeff if info.temporal_ensembling else None
    if (coeff is None) != (config.temporal_ensemble_coeff is None) or (
            coeff is not None and abs(coeff - config.temporal_ensemble_coeff) > 1e-9 * max(1.0, abs(coeff))):
        problems.append(f"temporal_ensemble_coeff: the blob has {coeff}, the config {config.temporal_ensemble_coeff}")
    if problems:
        raise ValueError(f"actengine policy: {where} does not match the features: " + "; ".join(problems))
