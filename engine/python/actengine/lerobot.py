"""A drop-in for LeRobot's inference step on the robot's own computer.

LeRobot's control loop (lerobot_record / control_utils.predict_action) turns the robot's observation
frame (a dict of numpy arrays keyed by feature names: HxWx3 uint8 camera frames, batch-less float32
states) into one raw action with a PyTorch ACTPolicy and its pre- and post-processors::

    action = predict_action(observation_frame, policy, device, preprocessor, postprocessor,
                            use_amp, task=task, robot_type=robot.robot_type)

ACTPolicy does the same from an .actb blob (normalisation, the n_action_steps queue or temporal
ensembling included, all inside actengine) and returns the same action, a float32 tensor of shape
(1, action_dim) on the CPU (numpy when torch is not installed)::

    policy = actengine.lerobot.ACTPolicy("model-int8.actb")
    action = policy.predict_action(observation_frame)
"""

import numpy as np

from ._actengine import Engine, Policy

STATE_KEY = "observation.state"


def model_input_keys(info):
    """The observation keys a model takes, in its order: each camera's, then the state's and the
    environment state's when it has them (ModelInfo: engine.model_info)."""
    keys = [camera.key for camera in info.cameras]
    if info.state_dim:
        keys.append(STATE_KEY)
    if info.env_state_dim:
        keys.append(info.env_state_key)
    return keys


class ACTPolicy:
    """LeRobot's ACTPolicy with its pre- and post-processors, running an .actb blob.

    ACTPolicy(blob, threads=0, isa="auto"); blob is a path to a file made by act_convert or
    actengine.convert. The observation's keys the model does not take (other features, "task") are
    ignored, as LeRobot's policy ignores them; a missing key, a wrong shape or dtype raises ValueError.
    """

    def __init__(self, blob, threads=0, isa="auto"):
        self.engine = Engine(blob, threads=threads, isa=isa)
        self._policy = Policy(self.engine)
        self._input_keys = model_input_keys(self.engine.model_info)
        try:
            import torch
        except ImportError:
            torch = None
        self._torch = torch

    @property
    def model_info(self):
        return self.engine.model_info

    def select_action(self, observation):
        """The raw action for this control step, shape (1, action_dim), float32."""
        inputs = {key: observation[key] for key in self._input_keys if key in observation}
        action = self._policy.select_action(inputs)[np.newaxis]
        return self._torch.from_numpy(action) if self._torch is not None else action

    def predict_action(self, observation, task=None, robot_type=None):
        """control_utils.predict_action(observation, policy, device, preprocessor, postprocessor, ...).

        task and robot_type are accepted for the same call shape; ACT takes no language input.
        """
        del task, robot_type
        return self.select_action(observation)

    def reset(self):
        """Starts a new episode: empties the action queue / ensemble (LeRobot's policy.reset())."""
        self._policy.reset()

    def will_infer_next(self):
        """True when the next select_action runs the network (the queue is empty, or ensembling)."""
        return self._policy.will_infer_next()
