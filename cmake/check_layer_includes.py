#!/usr/bin/env python3
"""Checks that every `#include "..."` of the source tree follows the layers (ctest: layer_includes).

Each folder may include only the layers below it (docs: architecture, "Layers"):
  kernels < weights/blob < weights/import < weights/quantize < graph < engine/src
          < engine/src/convert, engine/src/onnx, engine/vision < engine/media
Below the engine, the one public header a layer may include is actengine/status.h (the error
vocabulary). The public headers (engine/include/actengine) include only each other. The apps and
act_soak see the public headers, the apps' own and the headers exported on purpose (--exported,
the list cmake/ActLayer.cmake builds the apps' include root from). The peak probes (kernels/peak,
graph/peak_together.h, bench/probes) are a library of their own for the benchmarks; act_kernel_bench
and bench/tools benchmark the kernels and ops themselves and may see the kernels and graph layers.
test/ may see everything and is not checked.

Prints file:line, the include and the rule it breaks; exits 1 when any include breaks one.
Usage: check_layer_includes.py SOURCE_DIR [--exported HEADER...]
"""
import argparse
import os
import re
import sys

# Where a path belongs, by its longest matching prefix (files and included headers alike).
LAYER_OF_PREFIX = [
    ("kernels/peak/", "probes"),
    ("graph/peak_together.", "probes"),
    ("bench/probes/", "probes"),
    ("kernels/", "kernels"),
    ("weights/blob/", "weights/blob"),
    ("weights/import/", "weights/import"),
    ("weights/quantize/", "weights/quantize"),
    ("graph/", "graph"),
    ("engine/include/actengine/status.h", "status"),
    ("actengine/status.h", "status"),
    ("engine/include/actengine/", "public"),
    ("actengine/", "public"),
    ("engine/src/convert/", "engine/src/convert"),
    ("engine/src/onnx/", "engine/src/onnx"),
    ("engine/src/", "engine/src"),
    ("engine/vision/", "engine/vision"),
    ("engine/media/", "engine/media"),
    ("engine/python/", "python"),
    ("bench/act_kernel_bench.cc", "kernel_bench"),
    ("bench/tools/", "kernel_bench"),
    ("bench/", "bench"),
    ("apps/", "apps"),
]

CORE = ["kernels", "weights/blob", "weights/import", "weights/quantize", "graph"]

# What each layer may include besides itself. "exported" stands for the --exported headers.
MAY_INCLUDE = {
    "kernels": {"status"},
    "weights/blob": {"status"},
    "weights/import": {"weights/blob", "status"},
    "weights/quantize": {"weights/import", "weights/blob", "kernels", "status"},
    "graph": {"weights/blob", "kernels", "status"},
    "engine/src": {"graph", "weights/blob", "kernels", "public", "status"},
    "engine/src/convert": {"engine/src", "graph", *CORE, "public", "status"},
    "engine/src/onnx": {"engine/src", "graph", "weights/blob", "kernels", "public", "status"},
    "engine/vision": {"public", "status"},
    "engine/media": {"engine/src/convert", "weights/blob", "public", "status"},
    "public": {"status"},
    "status": set(),
    "python": {"public", "status"},
    "probes": {"graph", "weights/blob", "kernels", "status"},
    "kernel_bench": {"graph", "weights/blob", "kernels", "probes", "public", "status"},
    "bench": {"apps", "public", "status", "exported"},
    "apps": {"public", "status", "exported"},
}

RULES = {
    "kernels": "kernels/ includes only kernels/ and actengine/status.h",
    "weights/blob": "weights/blob includes only itself and actengine/status.h",
    "weights/import": "weights/import includes only weights/blob below it and actengine/status.h",
    "weights/quantize": "weights/quantize includes only weights/import, weights/blob, kernels and actengine/status.h",
    "graph": "graph includes only weights/blob, kernels and actengine/status.h",
    "engine/src": "engine/src includes graph, weights/blob, kernels and the public headers, not convert/onnx",
    "engine/src/convert": "engine/src/convert includes the engine and the layers below it",
    "engine/src/onnx": "engine/src/onnx includes the engine, graph, weights/blob, kernels and the public headers",
    "engine/vision": "engine/vision includes only the public headers",
    "engine/media": "engine/media includes the public headers, engine/src/convert and weights/blob",
    "public": "a public header includes only other public headers (they must stay self-contained)",
    "status": "actengine/status.h depends on nothing of the project's (every layer includes it)",
    "python": "the Python module uses only the public headers",
    "probes": "the peak probes include only kernels, graph, weights/blob and actengine/status.h",
    "kernel_bench": "act_kernel_bench sees the kernels, graph, the probes and the public headers, not the importers",
    "bench": "bench programs see the public headers, the apps' and the exported headers",
    "apps": "the apps see the public headers, their own and the headers exported on purpose (cmake/ActLayer.cmake)",
}

SOURCE_DIRS = ["kernels", "weights", "graph", "engine", "apps", "bench"]
SOURCE_SUFFIXES = (".h", ".hpp", ".cc", ".cpp", ".c", ".ino")
INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"')


def layer_of(path):
    best = None
    for prefix, layer in LAYER_OF_PREFIX:
        if path.startswith(prefix) and (best is None or len(prefix) > len(best[0])):
            best = (prefix, layer)
    return best[1] if best else None


def source_files(root):
    for top in SOURCE_DIRS:
        for dirpath, dirnames, filenames in os.walk(os.path.join(root, top)):
            dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
            for name in sorted(filenames):
                if name.endswith(SOURCE_SUFFIXES):
                    yield os.path.relpath(os.path.join(dirpath, name), root).replace(os.sep, "/")


def check(root, exported):
    problems = []
    for rel in source_files(root):
        layer = layer_of(rel)
        if layer is None:
            continue
        allowed = MAY_INCLUDE[layer]
        with open(os.path.join(root, rel), encoding="utf-8", errors="replace") as f:
            for number, line in enumerate(f, 1):
                m = INCLUDE.match(line)
                if not m:
                    continue
                header = m.group(1)
                target = layer_of(header)
                if target is None or target == layer:
                    continue  # a header of the same folder, or outside the layers (system, third party)
                if target in allowed or ("exported" in allowed and header in exported):
                    continue
                problems.append(f'{rel}:{number}: #include "{header}" ({target}): {RULES[layer]}')
    return problems


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source_dir")
    parser.add_argument("--exported", nargs="*", default=[], help="headers the apps may include")
    args = parser.parse_args()
    problems = check(args.source_dir, set(args.exported))
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} include(s) cross a layer the wrong way")
        return 1
    print("layer includes: ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
