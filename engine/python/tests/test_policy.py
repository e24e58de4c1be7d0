"""Policy (LeRobot's select_action), ChunkScheduler and the LeRobot drop-in against the fixtures'
select_action sequences."""

import numpy as np
import pytest

import actengine
import actengine.lerobot
from conftest import CAMERA, STATE, patched_checkpoint

TOLERANCE = dict(rtol=1e-4, atol=1e-4)


@pytest.fixture(scope="session")
def ensembling_blob(fixture, tmp_path_factory):
    """The fixture with the config its temporal_ensemble.actions were made with (same weights)."""
    folder = tmp_path_factory.mktemp(fixture.name + "-ensembling")
    checkpoint = patched_checkpoint(fixture, folder / "checkpoint", temporal_ensemble_coeff=0.01, n_action_steps=1)
    actengine.convert(checkpoint, folder / "model.actb", "fp32")
    return folder / "model.actb"


def test_select_action_queue_matches_lerobot(fixture, fp32_blob):
    policy = actengine.Policy(actengine.Engine(fp32_blob, threads=1))
    expected = fixture.ref["select_action.queue_sample0"]
    for episode in range(2):  # reset() starts the queue over
        policy.reset()
        for step in range(len(expected)):
            assert policy.will_infer_next() == (step == 0)
            action = policy.select_action(fixture.observation(0))
            assert action.dtype == np.float32 and action.shape == (2,)
            np.testing.assert_allclose(action, expected[step], err_msg=f"episode {episode} step {step}", **TOLERANCE)
        assert policy.will_infer_next()


def test_temporal_ensembling_matches_lerobot(fixture, ensembling_blob):
    engine = actengine.Engine(ensembling_blob, threads=1)
    assert engine.model_info.temporal_ensembling and engine.model_info.temporal_ensemble_coeff == 0.01
    policy = actengine.Policy(engine)
    actions = [policy.select_action(fixture.observation(i)) for i in range(fixture.samples)]
    np.testing.assert_allclose(actions, fixture.ref["temporal_ensemble.actions"], **TOLERANCE)


def test_lerobot_drop_in_gives_lerobots_actions(fixture, fp32_blob, ensembling_blob):
    import torch

    expected = fixture.ref["select_action.queue_sample0"]
    policy = actengine.lerobot.ACTPolicy(fp32_blob, threads=1)
    # The robot loop's frame: HxWx3 uint8, batch-less float32 state, and keys the model does not use.
    frame = {**fixture.observation(0), "observation.images.unused": np.zeros((4, 4, 3), np.uint8), "task": "drive"}
    for step in range(len(expected)):
        action = policy.predict_action(frame, task="drive", robot_type="lekiwi")
        assert isinstance(action, torch.Tensor) and action.dtype == torch.float32 and tuple(action.shape) == (1, 2)
        np.testing.assert_allclose(action.numpy()[0], expected[step], **TOLERANCE)
    policy.reset()
    assert policy.will_infer_next()
    np.testing.assert_allclose(policy.select_action(frame).numpy()[0], expected[0], **TOLERANCE)

    ensembling = actengine.lerobot.ACTPolicy(ensembling_blob, threads=1)
    actions = [ensembling.predict_action(fixture.observation(i)).numpy()[0] for i in range(fixture.samples)]
    np.testing.assert_allclose(actions, fixture.ref["temporal_ensemble.actions"], **TOLERANCE)


def test_lerobot_drop_in_names_a_missing_feature(act_tiny, tiny_blob):
    policy = actengine.lerobot.ACTPolicy(tiny_blob, threads=1)
    with pytest.raises(ValueError, match="missing observation key 'observation.state'"):
        policy.predict_action({CAMERA: act_tiny.observation(0)[CAMERA], "observation.velocity": np.zeros(2)})


def test_chunk_scheduler_serves_the_rows_of_a_chunk(act_tiny, tiny_engine):
    scheduler = actengine.ChunkScheduler(tiny_engine.model_info)
    assert scheduler.action_at(0) is None and scheduler.wants_inference(0)
    chunk = tiny_engine.infer(act_tiny.observation(0))
    scheduler.add(chunk, 5)  # observed at tick 5: row i is tick 5 + i
    assert scheduler.action_at(4) is None
    for row in range(10):
        np.testing.assert_array_equal(scheduler.action_at(5 + row), chunk[row])
    assert scheduler.action_at(15) is None
    assert not scheduler.wants_inference(8, 3) and scheduler.wants_inference(12, 3)
    with pytest.raises(ValueError, match=r"chunk: expected a float array of shape \(10, 2\), got float32 array of shape \(2, 10\)"):
        scheduler.add(chunk.T, 6)
    with pytest.raises(ValueError):
        scheduler.add(np.full((10, 2), np.nan, np.float32), 6)
    scheduler.clear()
    assert scheduler.action_at(5) is None


def test_policy_keeps_its_engine_alive(act_tiny, tiny_blob):
    policy = actengine.Policy(actengine.Engine(tiny_blob, threads=1))
    np.testing.assert_allclose(policy.select_action(act_tiny.observation(0)),
                               act_tiny.ref["select_action.queue_sample0"][0], **TOLERANCE)
