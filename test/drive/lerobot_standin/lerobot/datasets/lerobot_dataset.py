"""A minimal stand-in for LeRobot's LeRobotDataset (the part recording_to_lerobot.py uses), for the
tests on a machine without LeRobot: it checks each frame against the declared features the way
LeRobot does (every feature present, shapes and dtypes) and writes what it was given to
ROOT/standin.json for the test to read."""
import json
import os

import numpy as np


class LeRobotDataset:
    @classmethod
    def create(cls, repo_id, fps, features, root=None, robot_type=None, use_videos=True):
        if os.path.exists(root):
            raise FileExistsError(root)  # LeRobot refuses an existing root too
        dataset = cls()
        dataset.record = {"repo_id": repo_id, "fps": fps, "robot_type": robot_type, "use_videos": use_videos,
                          "features": {k: {**v, "shape": list(v["shape"])} for k, v in features.items()},
                          "episodes": []}
        dataset.root, dataset.features, dataset.buffer = root, features, []
        return dataset

    def add_frame(self, frame):  # LeRobot 0.4: the task is part of the frame
        if set(frame) != set(self.features) | {"task"}:
            raise ValueError(f"frame keys {sorted(frame)} do not match the features {sorted(self.features)} + task")
        stored = {"task": frame["task"]}
        for key, feature in self.features.items():
            value = np.asarray(frame[key])
            if tuple(value.shape) != tuple(feature["shape"]):
                raise ValueError(f"{key}: shape {value.shape}, the feature says {feature['shape']}")
            if feature["dtype"] in ("image", "video"):
                if value.dtype != np.uint8:
                    raise ValueError(f"{key}: dtype {value.dtype}")
                stored[key] = {"shape": list(value.shape), "mean": float(value.mean())}
            else:
                stored[key] = [float(v) for v in value]
        self.buffer.append(stored)

    def save_episode(self):
        self.record["episodes"].append(self.buffer)
        self.buffer = []

    def finalize(self):
        os.makedirs(self.root)
        with open(os.path.join(self.root, "standin.json"), "w") as f:
            json.dump(self.record, f)
