#!/usr/bin/env bash
# Cross-compiles the gemm_s8 kernels and their GoogleTest suite for AArch64 (static, no CMake) and
# runs them under qemu-user, so the NEON SDOT kernels are really executed on an x86 machine:
#   - with -cpu max (reports dotprod: neondot must be detected, run and match ref bit for bit),
#   - with -cpu cortex-a72 (no dotprod: only ref may be offered).
# A stopgap kernel-level check; the full aarch64 build + qemu stage runs all of act_tests.
# Needs g++-aarch64-linux-gnu, qemu-user and libgtest-dev:arm64.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
out="${1:-$root/build-aarch64-gemm}"
cxx="${CXX_AARCH64:-aarch64-linux-gnu-g++}"
mkdir -p "$out"
flags=(-std=c++20 -O2 -Wall -Wextra -Wpedantic -Wshadow -Wcast-align -Werror -I"$root")
kernel_srcs=("$root"/kernels/common/*.cc "$root"/kernels/gemm_s8/*.cc)
objs=()
for src in "${kernel_srcs[@]}"; do
  obj="$out/$(basename "$src" .cc).o"
  extra=(-ffp-contract=off)
  [[ "$src" == *_neondot.cc ]] && extra+=(-march=armv8.2-a+dotprod)
  "$cxx" "${flags[@]}" "${extra[@]}" -DACT_ENABLE_DCHECK -c "$src" -o "$obj"
  objs+=("$obj")
done
for src in "$root"/test/kernels/gemm_s8_tester.cc "$root"/test/kernels/test_gemm_s8.cc; do
  obj="$out/$(basename "$src" .cc).o"
  "$cxx" "${flags[@]}" -c "$src" -o "$obj"
  objs+=("$obj")
done
"$cxx" -static -o "$out/gemm_s8_tests" "${objs[@]}" -lgtest_main -lgtest -lpthread
echo "== qemu-aarch64 -cpu max (dotprod) =="
ACT_TEST_REQUIRE_ISAS=neondot qemu-aarch64 -cpu max "$out/gemm_s8_tests" --gtest_brief=1
echo "== qemu-aarch64 -cpu cortex-a72 (no dotprod) =="
qemu-aarch64 -cpu cortex-a72 "$out/gemm_s8_tests" --gtest_brief=1
