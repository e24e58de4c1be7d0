"""actengine.Engine against LeRobot's references: every fixture, every input form."""

import sys
import threading
import time

import numpy as np
import pytest

import actengine
from conftest import CAMERA, STATE

TOLERANCE = dict(rtol=1e-4, atol=1e-4)  # FP32 against LeRobot (the fixtures' README)


def test_model_info_describes_the_fixture(fixture, fp32_blob):
    info = actengine.Engine(fp32_blob, threads=1).model_info
    assert [(c.key, c.height, c.width) for c in info.cameras] == [(CAMERA, 96, 128)]
    assert (info.state_dim, info.env_state_dim, info.action_dim) == (2, 0, 2)
    assert (info.chunk_size, info.n_action_steps, info.temporal_ensembling) == (10, 10, False)
    assert info.precision == "fp32"
    assert info.isa and info.kernels
    assert len(info.action_low) == len(info.action_high) == 2
    assert info.action_names == []  # converted without act_convert --action-names
    assert len(info.state_low) == len(info.state_high) == 2
    assert all(lo < hi for lo, hi in zip(info.state_low, info.state_high))


def test_infer_matches_lerobot_on_every_sample(fixture, fp32_blob):
    engine = actengine.Engine(fp32_blob, threads=2)
    for i in range(fixture.samples):
        chunk = engine.infer(fixture.observation(i))
        assert chunk.dtype == np.float32 and chunk.shape == (10, 2)
        np.testing.assert_allclose(chunk, fixture.ref["output.action"][i], **TOLERANCE)
        normalized = engine.infer_normalized(fixture.observation(i))
        np.testing.assert_allclose(normalized, fixture.ref["output.action_normalized"][i], **TOLERANCE)


def input_forms(fixture, i):
    """Sample i in every form the module takes; each must give LeRobot's actions."""
    import torch

    frame = fixture.ref["input.observation.images.front.u8_nhwc"][i]
    chw = fixture.ref["input.observation.images.front"][i]
    state = fixture.ref["input.observation.state"][i]
    wide = np.zeros((96, 256, 3), np.uint8)
    wide[:, ::2] = frame

    class HasArray:  # an object exposing only __array__
        def __array__(self, dtype=None):
            return frame

    return {
        "float32 CHW in [0, 1]": {CAMERA: chw, STATE: state},
        "float64 state": {CAMERA: frame, STATE: state.astype(np.float64)},
        "batch dimension of 1": {CAMERA: frame[np.newaxis], STATE: state[np.newaxis]},
        "non-contiguous frame": {CAMERA: wide[:, ::2], STATE: state},
        "__array__": {CAMERA: HasArray(), STATE: list(state)},
        "torch tensors (DLPack)": {CAMERA: torch.from_numpy(frame.copy()), STATE: torch.from_numpy(state.copy())},
        "transposed torch tensor": {CAMERA: torch.from_numpy(np.ascontiguousarray(chw.transpose(1, 2, 0))).permute(2, 0, 1),
                                    STATE: torch.from_numpy(state.copy())},
    }


def test_every_input_form_gives_lerobots_actions(act_tiny, tiny_engine):
    for i in range(act_tiny.samples):
        for form, observation in input_forms(act_tiny, i).items():
            np.testing.assert_allclose(tiny_engine.infer(observation), act_tiny.ref["output.action"][i],
                                       err_msg=form, **TOLERANCE)


def bad_observations(good):
    frame, state = good[CAMERA], good[STATE]
    expect_image = "expected uint8 96x128x3"
    return [
        ({STATE: state}, "missing observation key 'observation.images.front': uint8 96x128x3"),
        ({CAMERA: frame}, "missing observation key 'observation.state': a float vector of 2 values"),
        ({**good, "observation.images.wrist": frame}, "unknown observation key 'observation.images.wrist'"),
        ({**good, 7: frame}, "observation keys are LeRobot feature names (str), got 7"),
        ({**good, CAMERA: frame.astype(np.float32)}, f"{CAMERA}: {expect_image}"),
        ({**good, CAMERA: frame.astype(np.float64).transpose(2, 0, 1)}, "got float64 array of shape (3, 96, 128)"),
        ({**good, CAMERA: frame.transpose(2, 0, 1)}, "got uint8 array of shape (3, 96, 128)"),
        ({**good, CAMERA: frame[:48]}, "got uint8 array of shape (48, 128, 3)"),
        ({**good, CAMERA: np.stack([frame, frame])}, "got uint8 array of shape (2, 96, 128, 3)"),
        ({**good, CAMERA: "front.png"}, f"{CAMERA}: {expect_image}"),
        ({**good, STATE: state[:1]}, "observation.state: expected a float vector of 2 values, got float32 array of shape (1,)"),
        ({**good, STATE: np.array([1, 2])}, "got int64 array of shape (2,)"),
        ({**good, STATE: np.array([0.5, np.inf], np.float32)}, "observation.state[1] is inf: every value must be finite"),
        ({**good, CAMERA: np.full((3, 96, 128), np.nan, np.float32)}, "(observation.images.front) contains NaN or Inf"),
        ({**good, CAMERA: np.full((3, 96, 128), 255, np.float32)}, "float images hold [0, 1]"),
    ]


@pytest.mark.parametrize("case", range(15))
def test_bad_input_raises_value_error_naming_it(act_tiny, tiny_engine, case):
    observation, message = bad_observations(act_tiny.observation(0))[case]
    with pytest.raises(ValueError) as error:
        tiny_engine.infer(observation)
    assert message in str(error.value)


def test_an_observation_that_is_not_a_dict_raises_type_error(act_tiny, tiny_engine):
    with pytest.raises(TypeError, match="observation"):
        tiny_engine.infer([act_tiny.observation(0)[CAMERA]])


def test_a_blob_that_cannot_be_run_raises_actengine_error(tiny_blob, tmp_path):
    bad = tmp_path / "not-a-blob.actb"
    bad.write_bytes(b"ACTB" + b"\0" * 60)
    with pytest.raises(actengine.Error, match="not-a-blob.actb': not an .actb file"):
        actengine.Engine(bad)
    with pytest.raises(actengine.Error, match="cannot open .*missing.actb"):
        actengine.Engine(tmp_path / "missing.actb")
    with pytest.raises(ValueError, match="unknown ISA 'sse9': this CPU runs ref"):  # a bad argument
        actengine.Engine(tiny_blob, isa="sse9")
    with pytest.raises(ValueError, match="unknown tuning 'zen9': choose auto or one of generic, zen4"):
        actengine.Engine(tiny_blob, uarch="zen9")


def test_the_kernels_say_which_core_they_are_tuned_for(tiny_blob):
    assert ", tuned for gracemont: " in actengine.Engine(tiny_blob, threads=1, uarch="gracemont").model_info.kernels


def test_a_second_thread_runs_while_the_engine_infers(act_tiny, tiny_engine):
    """The GIL is released during inference: a Python thread counting in a loop makes progress while
    infer() runs. With the switch interval made huge, the interpreter never takes the GIL from the main
    thread, so the counter can only move while the main thread gives the GIL up itself; the counter
    thread hands it back at every step (sleep(0)). Measured in loop iterations, not time."""
    progress = 0
    running = threading.Event()
    stop = threading.Event()

    def count():
        nonlocal progress
        while not stop.is_set():
            progress += 1
            running.set()
            time.sleep(0)

    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)
    thread = threading.Thread(target=count)
    thread.start()
    running.wait()
    observation = act_tiny.observation(0)
    during = 0
    try:
        for _ in range(20):
            before = progress
            tiny_engine.infer(observation)
            during += progress - before
    finally:
        stop.set()
        thread.join()
        sys.setswitchinterval(switch_interval)
    assert during > 0


def test_two_python_threads_can_share_one_engine(act_tiny, tiny_engine):
    """infer() runs without the GIL, so the Engine's own lock keeps two threads out of it at once."""
    results = {}

    def run(sample):
        results[sample] = [tiny_engine.infer(act_tiny.observation(sample)) for _ in range(5)]

    threads = [threading.Thread(target=run, args=(sample,)) for sample in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for sample, chunks in results.items():
        for chunk in chunks:
            np.testing.assert_allclose(chunk, act_tiny.ref["output.action"][sample], **TOLERANCE)
