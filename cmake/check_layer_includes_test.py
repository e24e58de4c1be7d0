#!/usr/bin/env python3
"""Shows that check_layer_includes.py fails on includes that cross a layer the wrong way (ctest:
layer_includes_planted): in a copy of the source tree with one violation planted at a time, and in a
small synthetic tree, each planted include must fail the check with its file:line and the rule, and
the unchanged copy must pass.

Usage: check_layer_includes_test.py SOURCE_DIR [--exported HEADER...]
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CHECK = os.path.join(HERE, "check_layer_includes.py")
SOURCE_DIRS = ["kernels", "weights", "graph", "engine", "apps", "bench"]

# (file to plant into, include line, rule text the report must name)
PLANTED = [
    ("kernels/common/isa.h", '#include "graph/graph.h"', "kernels/ includes only kernels/"),
    ("weights/blob/actb.cc", '#include "weights/import/safetensors.h"', "weights/blob includes only itself"),
    ("graph/graph.cc", '#include "actengine/engine.h"', "graph includes only weights/blob, kernels"),
    ("engine/src/engine.cc", '#include "engine/src/convert/int8_converter.h"', "not convert/onnx"),
    ("engine/include/actengine/engine.h", '#include "graph/graph.h"', "public header includes only other public"),
    ("apps/act_eval.cc", '#include "graph/graph.h"', "the apps see the public headers"),
    ("apps/act_eval.cc", '#include "weights/blob/model_config.h"', "the apps see the public headers"),
    ("graph/act_network.cc", '#include "kernels/peak/peak_probe.h"', "graph includes only"),
]


def run_check(root, exported):
    cmd = [sys.executable, CHECK, root]
    if exported:
        cmd += ["--exported", *exported]
    p = subprocess.run(cmd, capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr


def plant(path, line):
    """Adds `line` after the file's first #include line (or at the top); returns its line number."""
    with open(path, encoding="utf-8") as f:
        lines = f.readlines()
    at = next((i + 1 for i, l in enumerate(lines) if l.lstrip().startswith("#include")), 0)
    lines.insert(at, line + "\n")
    with open(path, "w", encoding="utf-8") as f:
        f.writelines(lines)
    return at + 1


def copy_tree(source, dest):
    for top in SOURCE_DIRS:
        shutil.copytree(os.path.join(source, top), os.path.join(dest, top), symlinks=True,
                        ignore=shutil.ignore_patterns(".*", "build*"))


def synthetic_tree(dest):
    files = {
        "kernels/gemm/gemm.h": '#include "actengine/status.h"\n',
        "weights/blob/blob.h": '#include "actengine/status.h"\n',
        "graph/net.h": '#include "kernels/gemm/gemm.h"\n#include "weights/blob/blob.h"\n',
        "engine/include/actengine/engine.h": '#include "actengine/status.h"\n',
        "engine/src/engine.cc": '#include "graph/net.h"\n#include "actengine/engine.h"\n',
        "apps/tool.cc": '#include "actengine/engine.h"\n#include "apps/tool.h"\n#include <vector>\n',
        "apps/tool.h": "#pragma once\n",
    }
    for rel, text in files.items():
        os.makedirs(os.path.dirname(os.path.join(dest, rel)), exist_ok=True)
        with open(os.path.join(dest, rel), "w", encoding="utf-8") as f:
            f.write(text)


def expect_failure(root, exported, rel, number, rule, label):
    code, out = run_check(root, exported)
    where = f"{rel}:{number}:"
    if code == 0 or where not in out or rule not in out:
        print(f"FAIL {label}: the check should fail naming {where} and \"{rule}\"; exit {code}, output:\n{out}")
        return False
    print(f"ok   {label}: {out.splitlines()[0]}")
    return True


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("source_dir")
    parser.add_argument("--exported", nargs="*", default=[])
    args = parser.parse_args()
    ok = True
    with tempfile.TemporaryDirectory(prefix="layer_includes_") as tmp:
        # The synthetic tree: clean, then one violation.
        synth = os.path.join(tmp, "synthetic")
        synthetic_tree(synth)
        code, out = run_check(synth, [])
        if code != 0:
            print(f"FAIL synthetic tree: a clean tree should pass; output:\n{out}")
            ok = False
        n = plant(os.path.join(synth, "kernels/gemm/gemm.h"), '#include "graph/net.h"')
        ok &= expect_failure(synth, [], "kernels/gemm/gemm.h", n, "kernels/ includes only kernels/", "synthetic kernels -> graph")

        # A copy of the real tree: clean, then each planted violation on its own.
        for i, (rel, line, rule) in enumerate(PLANTED):
            copy = os.path.join(tmp, f"copy{i}")
            copy_tree(args.source_dir, copy)
            if i == 0:
                code, out = run_check(copy, args.exported)
                if code != 0:
                    print(f"FAIL unchanged copy: the source tree itself should pass; output:\n{out}")
                    ok = False
            n = plant(os.path.join(copy, rel), line)
            ok &= expect_failure(copy, args.exported, rel, n, rule, f"{rel} + {line}")
            shutil.rmtree(copy)
    print("layer check catches planted violations" if ok else "layer check missed a planted violation")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
