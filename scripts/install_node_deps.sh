#!/usr/bin/env bash
# Installs the tests' Node packages, each pinned by its package-lock.json, into node_modules beside it
# (not committed). Idempotent.
#   test/onnx:    ONNX Runtime (npm's onnxruntime-node) for the ONNX export tests. It bundles its CPU
#                 binaries; its install script would fetch GPU ones from NuGet: skipped.
#   test/browser: playwright-core, which drives Debian's chromium (installed by install_deps.sh) in the
#                 web-page tests; it downloads no browser of its own.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
dir="$root/test/onnx"
if ! command -v npm >/dev/null; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "install_node_deps: installing npm"
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y --no-install-recommends npm
fi
# install_pinned DIR PACKAGE VERSION [env...]: npm ci in DIR unless PACKAGE@VERSION is already there.
install_pinned() {
  local dir="$root/$1" package="$2" version="$3"
  shift 3
  if node -e "process.exit(require('$dir/node_modules/$package/package.json').version === '$version' ? 0 : 1)" 2>/dev/null; then
    echo "install_node_deps: $package $version already installed"
    return
  fi
  echo "install_node_deps: installing $package $version into $dir/node_modules"
  (cd "$dir" && env "$@" npm ci --no-audit --no-fund --loglevel=error)
}
install_pinned test/onnx onnxruntime-node 1.30.0 ONNXRUNTIME_NODE_INSTALL=skip
install_pinned test/browser playwright-core 1.64.1 PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1
