"""A --policy.path folder from a LeRobot ACT checkpoint, with pip's actengine only (no act_convert):

    actengine-package CHECKPOINT FOLDER [--precision int8|fp32]
    python -m lerobot_policy_actengine.package CHECKPOINT FOLDER ...

converts CHECKPOINT into FOLDER/model.actb (actengine.convert) and writes what LeRobot loads beside
it: config.json (policy type "actengine", the model's features) and the pre/post-processor files.
These three files are those of `act_convert --package` (apps/deploy_package.cc), key for key; the
plugin's tests compare the two.
"""

import argparse
import json
import logging
from pathlib import Path

import actengine

BLOB = "model.actb"
STATE_KEY = "observation.state"


def _feature(kind, shape):
    return {"type": kind, "shape": list(shape)}


def lerobot_config(info):
    inputs = {}
    if info.state_dim:
        inputs[STATE_KEY] = _feature("STATE", [info.state_dim])
    if info.env_state_dim:
        inputs[info.env_state_key] = _feature("ENV", [info.env_state_dim])
    for camera in info.cameras:
        inputs[camera.key] = _feature("VISUAL", [3, camera.height, camera.width])
    config = {"type": "actengine", "n_obs_steps": 1, "input_features": inputs,
              "output_features": {"action": _feature("ACTION", [info.action_dim])},
              "device": "cpu", "use_amp": False, "use_peft": False, "push_to_hub": False}
    config.update(dict.fromkeys(["repo_id", "private", "tags", "license", "pretrained_path", "pretrained_revision"]))
    config.update({"chunk_size": info.chunk_size, "n_action_steps": info.n_action_steps,
                   "temporal_ensemble_coeff": info.temporal_ensemble_coeff if info.temporal_ensembling else None,
                   "blob": BLOB, "normalization": "blob", "threads": 0, "isa": "auto"})
    return config


def _device_step():
    return {"registry_name": "device_processor", "config": {"device": "cpu", "float_dtype": None}}


def lerobot_processors():
    pre = {"name": "policy_preprocessor", "steps": [
        {"registry_name": "rename_observations_processor", "config": {"rename_map": {}}},
        {"registry_name": "to_batch_processor", "config": {}},
        _device_step()]}
    post = {"name": "policy_postprocessor", "steps": [_device_step()]}
    return pre, post


def write_lerobot_files(folder, info):
    """config.json, policy_preprocessor.json and policy_postprocessor.json for the blob's ModelInfo."""
    folder = Path(folder)
    pre, post = lerobot_processors()
    (folder / "config.json").write_text(json.dumps(lerobot_config(info), indent=4) + "\n")
    (folder / "policy_preprocessor.json").write_text(json.dumps(pre, indent=2) + "\n")
    (folder / "policy_postprocessor.json").write_text(json.dumps(post, indent=2) + "\n")


def write_package(checkpoint, folder, precision="int8", **convert_options):
    """Converts `checkpoint` into folder/model.actb and writes LeRobot's files; returns convert's report."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    report = actengine.convert(checkpoint, folder / BLOB, precision, **convert_options)
    info = actengine.Engine(folder / BLOB, threads=1).model_info
    write_lerobot_files(folder, info)
    return report


def main(argv=None):
    parser = argparse.ArgumentParser(prog="actengine-package", description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", help="LeRobot ACT checkpoint folder (config.json, model.safetensors, processors)")
    parser.add_argument("folder", help="the folder to write: give it to LeRobot's commands as --policy.path")
    parser.add_argument("--precision", default="int8", choices=["int8", "fp32"])
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    # INT8 here is dynamic (activations quantised at run time): calibrated static INT8 needs frames,
    # which act_convert --package --calib reads from folders, videos and datasets.
    options = {"mode": "dynamic"} if args.precision == "int8" else {}
    report = write_package(args.checkpoint, args.folder, args.precision, **options)
    for note in report.get("notes", []):
        logging.info("note: %s", note)
    print(f"wrote {args.folder}: {BLOB} ({report['model']}, {report['precision']}, {report['bytes']} bytes), "
          "config.json, policy_preprocessor.json, policy_postprocessor.json")


if __name__ == "__main__":
    main()
