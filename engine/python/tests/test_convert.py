"""actengine.convert against act_convert: the same blobs, reports and error messages."""

import json
import os
import subprocess

import numpy as np
import pytest

import actengine
from conftest import CAMERA, require

TOLERANCE = dict(rtol=1e-4, atol=1e-4)


def act_convert(*args):
    """Runs the act_convert of this build tree (CTest passes its path): (exit code, stderr)."""
    binary = os.environ.get("ACT_CONVERT_BIN", "")
    require(binary)
    run = subprocess.run([binary, *map(str, args)], capture_output=True, text=True, check=False)
    return run.returncode, run.stderr


def test_int8_round_trip_with_its_report(act_tiny, tmp_path):
    lines = []
    result = actengine.convert(act_tiny.dir, tmp_path / "int8.actb", mode="dynamic", threads=2, progress=lines.append)
    assert result["precision"] == "int8"
    assert result["bytes"] == (tmp_path / "int8.actb").stat().st_size
    report = result["report"]
    assert report["calibration"] == "" and report["int8_bytes"] == result["bytes"] < report["fp32_bytes"]
    assert report["action_keys"] == 2 and len(report["action_error"]["per_dim_mse"]) == 2
    assert 0 < report["action_error"]["mse"] < 1e-2
    assert lines and all(isinstance(line, str) for line in lines)

    # The same conversion by act_convert writes the same report (but for its wall time).
    code, _ = act_convert(act_tiny.dir, "-o", tmp_path / "cli.actb", "--precision", "int8", "--mode", "dynamic",
                          "--threads", 2, "--report", tmp_path / "cli.json", "-q")
    assert code == 0
    cli_report = json.loads((tmp_path / "cli.json").read_text())
    assert {k: v for k, v in cli_report.items() if k != "seconds"} == {k: v for k, v in report.items() if k != "seconds"}
    assert (tmp_path / "cli.actb").read_bytes() == (tmp_path / "int8.actb").read_bytes()

    # The INT8 blob runs, close to LeRobot's FP32 actions (within the report's own error scale).
    engine = actengine.Engine(tmp_path / "int8.actb", threads=1)
    assert engine.model_info.precision == "int8 dynamic"
    chunk = engine.infer_normalized(act_tiny.observation(0))
    assert np.abs(chunk - act_tiny.ref["output.action_normalized"][0]).max() < 0.2


def test_static_int8_calibrates_on_observation_dicts(act_tiny, tmp_path):
    frames = [act_tiny.observation(i) for i in range(act_tiny.samples)]
    frames[3] = {CAMERA: frames[3][CAMERA]}  # a frame without state: sampled from the statistics
    result = actengine.convert(act_tiny.dir, tmp_path / "static.actb", "int8", calib=frames, calib_samples=3,
                               holdout=1, calib_method="minmax", layer_report=False)
    report = result["report"]
    assert (report["calibration"], report["calibration_frames"], report["holdout_frames"]) == ("minmax", 3, 1)
    assert report["layers"] == []
    assert actengine.Engine(tmp_path / "static.actb").model_info.precision == "int8 static"
    # The linear inputs' codes, forced: every input listed, none per tensor.
    result = actengine.convert(act_tiny.dir, tmp_path / "tokens.actb", "int8", calib=frames, calib_samples=3,
                               holdout=1, layer_report=False, linear_inputs="per-token")
    inputs = result["report"]["linear_inputs"]
    assert inputs and {i["codes"] for i in inputs} == {"per_token"}


def test_fp32_conversion_matches_act_convert(act_tiny, tiny_blob, tmp_path):
    code, _ = act_convert(act_tiny.dir, "-o", tmp_path / "cli.actb", "-q")
    assert code == 0
    assert (tmp_path / "cli.actb").read_bytes() == tiny_blob.read_bytes()


@pytest.mark.parametrize("checkpoint", ["missing-folder", "blob"])
def test_conversion_errors_carry_act_converts_message(act_tiny, tiny_blob, tmp_path, checkpoint):
    source = tmp_path / "missing-folder" if checkpoint == "missing-folder" else tiny_blob
    code, stderr = act_convert(source, "-o", tmp_path / "cli.actb")
    assert code == 1
    with pytest.raises((actengine.Error, ValueError)) as error:
        actengine.convert(source, tmp_path / "py.actb", "fp32")
    assert stderr.strip().endswith("act_convert: error: " + str(error.value))
    assert not (tmp_path / "py.actb").exists()


@pytest.mark.parametrize("arguments, message", [
    (dict(precision="fp16"), "precision must be 'fp32' or 'int8', got 'fp16'"),
    (dict(), "static quantization needs calibration frames: calib=[observation dict, ...] or calib=path (a folder"),
    (dict(precision="fp32", mode="dynamic"), "mode, calib and max_mse need precision='int8'"),
    (dict(mode="mixed", calib=[{}]), "mode='mixed' needs target_mse"),
    (dict(mode="fast"), "mode must be 'dynamic', 'static' or 'mixed', got 'fast'"),
    (dict(mode="dynamic", calib_method="median"), "median"),
    (dict(mode="dynamic", config="config.json"), "the .pth options (config, stats, ...) do not apply"),
    (dict(mode="dynamic", attention="int4"), "attention must be 'auto', 'int8' or 'fp32', got 'int4'"),
    (dict(mode="dynamic", linear_inputs="per-row"), "linear_inputs must be 'auto', 'per-token' or 'per-tensor', got 'per-row'"),
    (dict(mode="dynamic", linear_inputs="per-tensor"), "linear_inputs needs calibration"),
    (dict(mode="dynamic", temporal_ensemble_coeff=0.01, no_temporal_ensembling=True), "not both"),
    (dict(calib=[{CAMERA: np.zeros((3, 96, 128), np.float32)}]), "observation.images.front: expected uint8 96x128x3"),
])
def test_bad_arguments_raise_value_error(act_tiny, tmp_path, arguments, message):
    with pytest.raises(ValueError) as error:
        actengine.convert(act_tiny.dir, tmp_path / "out.actb", **arguments)
    assert message in str(error.value)
    assert not (tmp_path / "out.actb").exists()


def test_attention_and_deployment_settings_reach_the_blob(act_tiny, tmp_path):
    result = actengine.convert(act_tiny.dir, tmp_path / "f.actb", mode="dynamic", threads=2, attention="fp32")
    assert result["report"]["attention"] == {"precision": "fp32"}
    result = actengine.convert(act_tiny.dir, tmp_path / "i.actb", mode="dynamic", threads=2, attention="int8",
                               n_action_steps=1, temporal_ensemble_coeff=0.01)
    assert result["report"]["attention"]["precision"] == "int8"
    info = actengine.Engine(tmp_path / "i.actb").model_info
    assert (info.n_action_steps, info.temporal_ensembling) == (1, True)
    assert info.temporal_ensemble_coeff == pytest.approx(0.01)


def test_a_missed_max_mse_writes_nothing_and_says_what_to_try(act_tiny, tmp_path):
    with pytest.raises(actengine.Error, match="max_mse 1e-12 missed: try mode='mixed', target_mse=1e-12"):
        actengine.convert(act_tiny.dir, tmp_path / "out.actb", mode="dynamic", max_mse=1e-12)
    assert not (tmp_path / "out.actb").exists()
