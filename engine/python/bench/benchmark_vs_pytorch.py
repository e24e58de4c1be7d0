"""Times one inference of a LeRobot ACT checkpoint in PyTorch and in actengine (FP32 and INT8), from
Python, on the checkpoint's reference observations; prints a table (docs/python-and-lerobot.md).

    PYTHONPATH=build/python /usr/bin/python3 engine/python/bench/benchmark_vs_pytorch.py CHECKPOINT \\
        [--threads 2] [--runs 20] [--shared ../shared]

CHECKPOINT is a LeRobot folder with a reference.safetensors (the shared fixtures, or the generated
test checkpoints of test/tools/generate_test_checkpoints.sh). The PyTorch side is the shared
float32 reference forward (shared/tools/act_reference/spec_forward.py: LeRobot's computation in
plain torch ops, the same math as LeRobot's ACTPolicy). INT8 is calibrated (static) on the
checkpoint's reference frames. Medians of --runs runs after two warm-up runs.
"""

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import actengine


def median_ms(run, runs):
    for _ in range(2):
        run()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        run()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--shared", type=Path, default=Path(__file__).resolve().parents[3] / ".." / "shared")
    args = parser.parse_args()

    sys.path.insert(0, str(args.shared / "tools" / "act_reference"))
    import torch
    import spec_forward
    from act_harness import stio

    torch.set_num_threads(args.threads)
    ref = stio.load_file_numpy(args.checkpoint / "reference.safetensors")
    cameras = [key[len("input."):] for key in ref if key.startswith("input.observation.images.") and
               not key.endswith(".u8_nhwc")]
    samples = ref["input.observation.state"].shape[0]
    observations = [{**{c: ref[f"input.{c}.u8_nhwc"][i] for c in cameras},
                     "observation.state": ref["input.observation.state"][i]} for i in range(samples)]

    checkpoint = spec_forward.Ckpt(args.checkpoint, torch.float32)
    images = {c: torch.from_numpy(ref[f"input.{c}"][0]) for c in cameras}
    state = torch.from_numpy(ref["input.observation.state"][0])

    def torch_forward():
        with torch.no_grad():
            spec_forward.forward(checkpoint, images, state)

    rows = [("PyTorch " + torch.__version__ + " float32", median_ms(torch_forward, args.runs))]
    with tempfile.TemporaryDirectory() as folder:
        for precision, options in [("fp32", {}), ("int8", dict(calib=observations, calib_samples=samples,
                                                               holdout=1, layer_report=False))]:
            blob = Path(folder) / f"{precision}.actb"
            actengine.convert(args.checkpoint, blob, precision, **options)
            engine = actengine.Engine(blob, threads=args.threads)
            rows.append((f"actengine {engine.model_info.precision} ({engine.model_info.isa})",
                         median_ms(lambda: engine.infer(observations[0]), args.runs)))
        summary = engine.model_info.summary
    print(f"{args.checkpoint.name}: {summary}; {args.threads} threads, median of {args.runs}")
    for name, ms in rows:
        print(f"  {name:<40} {ms:9.1f} ms   {rows[0][1] / ms:5.1f}x")


if __name__ == "__main__":
    main()
