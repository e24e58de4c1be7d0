#!/usr/bin/env bash
# Installs the tests' Node packages (ONNX Runtime, npm's onnxruntime-node, pinned in
# test/onnx/package-lock.json) into test/onnx/node_modules (not committed). Idempotent.
# onnxruntime-node bundles its CPU binaries; its install script would fetch GPU ones from NuGet: skipped.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
dir="$root/test/onnx"
if ! command -v npm >/dev/null; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "install_node_deps: installing npm"
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y --no-install-recommends npm
fi
if node -e "process.exit(require('$dir/node_modules/onnxruntime-node/package.json').version === '1.30.0' ? 0 : 1)" 2>/dev/null; then
  echo "install_node_deps: onnxruntime-node 1.30.0 already installed"
  exit 0
fi
echo "install_node_deps: installing onnxruntime-node into $dir/node_modules"
(cd "$dir" && ONNXRUNTIME_NODE_INSTALL=skip npm ci --no-audit --no-fund --loglevel=error)
