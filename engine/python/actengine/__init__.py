"""actengine: run a converted LeRobot ACT policy (.actb) on the CPU, in FP32 or INT8.

    import actengine
    engine = actengine.Engine("model.actb")
    chunk = engine.infer({"observation.images.front": frame_hwc_uint8, "observation.state": state})
    policy = actengine.Policy(engine)          # LeRobot's select_action: queue / temporal ensembling
    action = policy.select_action(observation)
    report = actengine.convert("pretrained_model", "model-int8.actb", mode="dynamic")

actengine.lerobot is the drop-in for LeRobot's inference step in a robot loop.
"""

from ._actengine import (
    CameraInfo,
    ChunkScheduler,
    Engine,
    Error,
    ModelInfo,
    Policy,
    __version__,
    convert,
)

__all__ = ["CameraInfo", "ChunkScheduler", "Engine", "Error", "ModelInfo", "Policy", "__version__", "convert"]
