#!/usr/bin/python3
"""Write PyTorch .pth checkpoints (torch.save, Debian's python3-torch) for act_convert's .pth tests.

    make_test_pth.py --shared ../shared --out build/test/data/checkpoints/pth

From the shared fixtures act-tiny (current layout: no statistics in the weights) and act-tiny-legacy
(statistics as buffers in the weights), the same tensors saved the ways training scripts save them:
zip and legacy (_use_new_zipfile_serialization=False) format, plain or wrapped in
{"model_state_dict": ..., "epoch": ..., "optimizer_state_dict": ...}, keys with and without the
"model." prefix.  The tests convert each and compare the blob with the fixture folder's.

Also: views.pth (every dtype, non-contiguous and offset views, shared storages, 0-d tensors,
nn.Parameter; expected values in views_expected.safetensors), and malicious pickles that must be
refused without running anything (evil_*.pth; if one ran, it would create the file PWNED).
"""

from __future__ import annotations

import argparse
import collections
import io
import json
import os
import pickle
import sys
import zipfile
from pathlib import Path

import torch


def load_safetensors(path: Path) -> "collections.OrderedDict[str, torch.Tensor]":
    import numpy as np
    sys.path.insert(0, str(SHARED / "tools" / "act_reference"))
    from act_harness import stio  # noqa: E402
    arrays = stio.load_file_numpy(path)
    return collections.OrderedDict((k, torch.from_numpy(np.array(v))) for k, v in sorted(arrays.items()))


def without_model_prefix(sd):
    return collections.OrderedDict((k[len("model."):] if k.startswith("model.") else k, v) for k, v in sd.items())


def wrapped(sd, key="model_state_dict"):
    # What a typical training loop saves: the weights, the epoch, optimizer state (tensors of its own).
    params = [torch.nn.Parameter(torch.ones(3, 2)), torch.nn.Parameter(torch.zeros(4))]
    opt = torch.optim.Adam(params, lr=1e-4)
    sum(p.sum() for p in params).backward()
    opt.step()
    return {key: sd, "epoch": 42, "optimizer_state_dict": opt.state_dict(), "best_loss": 0.125,
            "tag": b"rover-v1", "history": [1.0, 0.5, (2, "x")], "flags": {"amp": False, "seed": None}}


def save(obj, path: Path, legacy=False, protocol=2):
    torch.save(obj, path, _use_new_zipfile_serialization=not legacy, pickle_protocol=protocol)


def write_torch_like_zip(path: Path, pickle_bytes: bytes):
    # The container torch.save writes, around a pickle torch never would.
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED) as z:
        z.writestr("archive/data.pkl", pickle_bytes)
        z.writestr("archive/version", "3\n")


class RunsShell:
    """Unpickling this with pickle.load would run a shell command."""
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


class CallsEval:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (eval, (f"open({self.marker!r}, 'w')",))


def main() -> int:
    global SHARED
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shared", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    SHARED = args.shared.resolve()
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(0)

    tiny = load_safetensors(SHARED / "fixtures" / "act-tiny" / "model.safetensors")
    legacy = load_safetensors(SHARED / "fixtures" / "act-tiny-legacy" / "model.safetensors")

    # act-tiny (statistics come from --stats / --config).
    save(tiny, out / "tiny_plain.pth")
    save(wrapped(without_model_prefix(tiny)), out / "tiny_wrapped_noprefix.pth")
    save(tiny, out / "tiny_plain_legacyformat.pth", legacy=True)
    save(wrapped(tiny, key="state_dict"), out / "tiny_wrapped_proto4.pth", protocol=4)
    half = collections.OrderedDict((k, v.half()) for k, v in tiny.items())
    save(half, out / "tiny_f16.pth")
    # The same half-precision weights as a LeRobot folder, the reference for tiny_f16.pth.
    folder = out / "act-tiny-f16"
    folder.mkdir(exist_ok=True)
    for f in (SHARED / "fixtures" / "act-tiny").iterdir():
        if f.suffix == ".json" or (f.suffix == ".safetensors" and f.name.startswith("policy_")):
            (folder / f.name).write_bytes(f.read_bytes())
    sys.path.insert(0, str(SHARED / "tools" / "act_reference"))
    from act_harness import stio  # noqa: E402
    stio.save_file({k: v.numpy() for k, v in half.items()}, folder / "model.safetensors")
    # act-tiny-legacy (statistics are buffers in the state dict).
    save(legacy, out / "tinylegacy_plain.pth")
    save(wrapped(without_model_prefix(legacy)), out / "tinylegacy_wrapped_noprefix_legacyformat.pth", legacy=True)

    # The dataset statistics as LeRobot writes meta/stats.json (nested lists, every feature).
    stats = load_safetensors(SHARED / "fixtures" / "act-tiny" / "policy_preprocessor_step_3_normalizer_processor.safetensors")
    stats_json = collections.OrderedDict()
    for name, t in stats.items():
        feature, stat = name.rsplit(".", 1)
        stats_json.setdefault(feature, collections.OrderedDict())[stat] = t.tolist()
    (out / "tiny_stats.json").write_text(json.dumps(stats_json, indent=2))

    # Views and dtypes.
    base = torch.arange(24, dtype=torch.float32).reshape(4, 6) / 7
    views = collections.OrderedDict()
    views["f32"] = base.clone()
    views["f64"] = base.double()
    views["f16"] = base.half()
    views["bf16"] = base.bfloat16()
    views["i64"] = torch.arange(5, dtype=torch.int64) - 2
    views["transposed"] = base.t()
    views["offset"] = base.view(-1)[5:11]
    views["column"] = base[:, 2]
    views["shared_a"] = base[1]
    views["shared_b"] = base[2:4]
    views["scalar"] = torch.tensor(3.5)
    views["empty"] = torch.zeros(0, 3)
    views["parameter"] = torch.nn.Parameter(base[:2, :2].clone())
    save(views, out / "views.pth")
    save(views, out / "views_legacyformat.pth", legacy=True)
    save(views, out / "views_proto4.pth", protocol=4)
    expected = collections.OrderedDict()
    for k, v in views.items():
        v = v.detach()
        expected[k] = v.contiguous() if v.dtype == torch.int64 else v.float().contiguous()
    stio.save_file({k: v.numpy() for k, v in expected.items()}, out / "views_expected.safetensors")

    # Malicious pickles in torch's containers. Loading any of them with pickle would touch PWNED.
    marker = str((out / "PWNED").resolve())
    write_torch_like_zip(out / "evil_os_system.pth", pickle.dumps({"w": RunsShell(marker)}, protocol=2))
    write_torch_like_zip(out / "evil_stack_global.pth", pickle.dumps(RunsShell(marker), protocol=4))
    write_torch_like_zip(out / "evil_eval.pth", pickle.dumps(CallsEval(marker), protocol=2))
    # A real state dict with the payload beside it (an "epoch" that runs a command).
    buf = io.BytesIO()
    torch.save({"model_state_dict": collections.OrderedDict(w=torch.ones(2)), "epoch": RunsShell(marker)}, buf)
    (out / "evil_in_wrapper.pth").write_bytes(buf.getvalue())
    # Legacy format: magic, version, sys_info, then the payload.
    legacy_head = b"".join(pickle.dumps(x, protocol=2) for x in
                           (0x1950a86a20f9469cfc6c, 1001, {"protocol_version": 1001, "little_endian": True}))
    (out / "evil_legacyformat.pth").write_bytes(legacy_head + pickle.dumps(RunsShell(marker), protocol=2))
    # A 4 GB string length in a 40-byte pickle.
    write_torch_like_zip(out / "evil_huge_length.pth", b"\x80\x02X\xf0\xff\xff\xffabc.")
    # A storage entry that inflates far past what its tensor needs (2 floats declared, 64 MiB of zeros
    # deflated to about 64 kB): refused from the sizes, before anything is inflated.
    buf = io.BytesIO()
    torch.save(collections.OrderedDict(w=torch.ones(2)), buf)
    with zipfile.ZipFile(buf) as src, zipfile.ZipFile(out / "evil_inflated_storage.pth", "w") as dst:
        for info in src.infolist():
            if info.filename.endswith("/data/0"):
                dst.writestr(info.filename, bytes(64 << 20), compress_type=zipfile.ZIP_DEFLATED)
            else:
                dst.writestr(info, src.read(info.filename))
    # Not a checkpoint at all.
    (out / "not_a_checkpoint.pth").write_bytes(b"hello, this is text\n")
    print(f"wrote {len(list(out.glob('*.pth')))} .pth files to {out}")
    return 0


SHARED = Path()

if __name__ == "__main__":
    sys.exit(main())
