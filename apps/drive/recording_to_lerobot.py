#!/usr/bin/env python3
"""Turns an act_drive recording (act_drive --record DIR) into a LeRobot dataset, for training.

Run it on the training machine, where LeRobot is installed (pip install lerobot): it writes the
dataset through LeRobot's own LeRobotDataset API, so the result is whatever format that LeRobot
version writes and trains on.

    python3 recording_to_lerobot.py REC_DIR --repo-id me/rover-laps --root ./rover-laps \
        --task "drive the track" [--drivers manual] [--min-frames 30]

Each control tick of the recording (ticks.csv) with a camera frame becomes one dataset frame:
the tick's frame (tick_frames/, already at the model's input size) as the image, the state the
model would have seen as observation.state, and the command actually sent (in the model's units) as
the action. Only ticks whose command came from --drivers are kept (default: manual, i.e. the
demonstrations driven by hand); each unbroken run of them is one episode.
"""
import argparse
import csv
import inspect
import json
import os
import sys


def read_recording(directory):
    with open(os.path.join(directory, "meta.json")) as f:
        meta = json.load(f)
    with open(os.path.join(directory, "ticks.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and "driver" not in rows[0]:
        sys.exit(f"{directory}: ticks.csv has no driver column: recorded by an act_drive older than per-tick recording")
    return meta, rows


def episodes(rows, drivers, min_frames):
    """Unbroken runs of ticks sent by one of `drivers` that have a frame; runs shorter than min_frames dropped.
    (A tick the loop skipped because the machine stalled leaves no row and does not end a run.)"""
    runs, run = [], []
    for row in rows:
        if row["driver"] in drivers and row["frame"] and row["sent"] == "1":
            run.append(row)
            continue
        if len(run) >= min_frames:
            runs.append(run)
        run = []
    if len(run) >= min_frames:
        runs.append(run)
    return runs


def values(row, prefix, count):
    return [float(row[f"{prefix}.{i}"]) for i in range(count)]


def command_columns(row):
    """ticks.csv's command columns in order: command.<name> after the blob's action names, or command.0, ..."""
    return [key for key in row if key.startswith("command.")]


def convert(directory, repo_id, root, task, drivers, min_frames, use_videos, dataset_class, load_image):
    meta, rows = read_recording(directory)
    state_dim = sum(1 for key in rows[0] if key.startswith("state.")) if rows else 0
    commands = command_columns(rows[0]) if rows else []
    action_dim = len(commands)
    # The dataset's action names: the recording's (steering, throttle) when the blob named them.
    action_names = [c[len("command."):] for c in commands]
    if all(name.isdigit() for name in action_names):
        action_names = [f"action.{name}" for name in action_names]
    runs = episodes(rows, drivers, min_frames)
    if not runs:
        sys.exit(f"{directory}: no run of at least {min_frames} ticks driven by {', '.join(sorted(drivers))} "
                 f"(see the driver column of ticks.csv; --drivers and --min-frames choose)")
    image_key = meta["image_key"]
    features = {
        image_key: {"dtype": "video" if use_videos else "image",
                    "shape": (meta["image_height"], meta["image_width"], 3),
                    "names": ["height", "width", "channels"]},
        "action": {"dtype": "float32", "shape": (action_dim,), "names": action_names},
    }
    if state_dim:
        features["observation.state"] = {"dtype": "float32", "shape": (state_dim,),
                                         "names": [f"state.{i}" for i in range(state_dim)]}
    dataset = dataset_class.create(repo_id=repo_id, fps=round(meta["control_hz"]), root=root, robot_type="rc_rover",
                                   features=features, use_videos=use_videos)
    # LeRobot up to 0.3 takes the task as an argument of add_frame, later versions inside the frame.
    task_argument = "task" in inspect.signature(dataset.add_frame).parameters
    for run in runs:
        for row in run:
            frame = {image_key: load_image(os.path.join(directory, row["frame"])),
                     "action": [float(row[c]) for c in commands]}
            if state_dim:
                frame["observation.state"] = values(row, "state", state_dim)
            if task_argument:
                dataset.add_frame(frame, task=task)
            else:
                dataset.add_frame({**frame, "task": task})
        dataset.save_episode()
    if hasattr(dataset, "finalize"):
        dataset.finalize()
    return [len(run) for run in runs]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("recording", help="the folder act_drive --record wrote")
    parser.add_argument("--repo-id", required=True, help="the dataset's name, e.g. me/rover-laps")
    parser.add_argument("--root", required=True, help="where to write the dataset (a new folder)")
    parser.add_argument("--task", default="drive the track", help="the task text stored with every frame")
    parser.add_argument("--drivers", default="manual",
                        help="comma-separated drivers whose ticks to keep: manual, ai, ai-steer (default: manual)")
    parser.add_argument("--min-frames", type=int, default=30, help="drop shorter episodes (default 30)")
    parser.add_argument("--images", action="store_true", help="store PNG images instead of videos")
    args = parser.parse_args(argv)
    try:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset
    except ImportError:
        try:
            from lerobot.common.datasets.lerobot_dataset import LeRobotDataset  # LeRobot before 0.3
        except ImportError:
            sys.exit("LeRobot is not installed here: run this on the training machine (pip install lerobot)")
    import numpy as np
    from PIL import Image

    def load_image(path):
        return np.asarray(Image.open(path).convert("RGB"))

    lengths = convert(args.recording, args.repo_id, args.root, args.task, set(args.drivers.split(",")), args.min_frames,
                      not args.images, LeRobotDataset, load_image)
    print(f"{args.root}: {len(lengths)} episodes, {sum(lengths)} frames ({', '.join(map(str, lengths))})")


if __name__ == "__main__":
    main()
