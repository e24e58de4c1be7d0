"""ActengineConfig: the config.json of a folder written by `act_convert --package` (type "actengine")."""

from dataclasses import dataclass

from lerobot.configs.policies import PreTrainedConfig
from lerobot.configs.types import FeatureType

# Where normalisation happens. "blob": the blob normalises the observation and un-normalises the
# actions (the engine's infer); the folder's processors then only batch and place tensors. The only
# value this version writes and runs; a folder saying anything else is refused at load.
NORMALIZATION_IN_BLOB = "blob"


@PreTrainedConfig.register_subclass("actengine")
@dataclass
class ActengineConfig(PreTrainedConfig):
    """A converted ACT policy run by actengine. input_features / output_features are the checkpoint's
    (LeRobot's checks against the robot's and the dataset's features work as for its ACT);
    chunk_size, n_action_steps and temporal_ensemble_coeff are the blob's (they are checked against
    it at load: act_convert bakes them in)."""

    chunk_size: int = 100
    n_action_steps: int = 100
    temporal_ensemble_coeff: float | None = None

    blob: str = "model.actb"  # the blob's file name inside the folder
    normalization: str = NORMALIZATION_IN_BLOB
    threads: int = 0  # engine threads; 0 = the engine's default (the machine's cores)
    isa: str = "auto"  # kernels' instruction set: "auto" or a name act_bench --isa lists

    def __post_init__(self):
        super().__post_init__()
        if self.n_action_steps > self.chunk_size:
            raise ValueError(f"n_action_steps ({self.n_action_steps}) cannot exceed chunk_size ({self.chunk_size})")
        if self.temporal_ensemble_coeff is not None and self.n_action_steps > 1:
            raise NotImplementedError("temporal ensembling needs n_action_steps == 1 (as LeRobot's ACT)")
        if self.normalization != NORMALIZATION_IN_BLOB:
            raise ValueError(f"config.json says normalization '{self.normalization}'; this actengine plugin runs "
                             f"folders whose blob normalises ('{NORMALIZATION_IN_BLOB}'): write the folder again with act_convert --package")

    def get_optimizer_preset(self):
        raise NotImplementedError("an actengine policy runs a converted blob: it cannot be trained")

    def get_scheduler_preset(self):
        return None

    def validate_features(self) -> None:
        if not self.image_features and not self.env_state_feature:
            raise ValueError("You must provide at least one image or the environment state among the inputs.")
        if self.action_feature is None:
            raise ValueError("config.json of an actengine policy needs the output feature 'action'")

    @property
    def observation_delta_indices(self) -> None:
        return None

    @property
    def action_delta_indices(self) -> list:
        return list(range(self.chunk_size))

    @property
    def reward_delta_indices(self) -> None:
        return None

    def visual_keys(self):
        return [key for key, ft in (self.input_features or {}).items() if ft.type is FeatureType.VISUAL]
