#!/usr/bin/env python3
"""Static instruction mix of the innermost loops of a disassembled kernel object.

Prints every loop (a backward branch and the instructions from its target to it) that holds at
least --min-mac multiply-accumulate instructions (sdot / vpdpbusd / vpmaddwd), with the count of
each mnemonic: the basis of the NEON %-of-peak estimate in kernels/README.md, where no A76 is at
hand to time the kernel (qemu-user executes it but does not model timing).

With --mca CPU each loop also goes through llvm-mca (Debian's llvm) for that core, e.g.
--mca cortex-a76 for the Raspberry Pi 5: the projected cycles per iteration and the share of the
core's MAC peak (--peak-macs per cycle; 32 for SDOT on the A76's two 128-bit pipes) the loop can
reach, a projection, not a measurement.

  aarch64-linux-gnu-g++ -std=c++20 -O3 -DNDEBUG -ffp-contract=off -march=armv8.2-a+dotprod -I. \
      -c kernels/gemm_s8/gemm_s8_neondot.cc -o /tmp/gemm_s8_neondot.o
  aarch64-linux-gnu-objdump -d --no-show-raw-insn -C /tmp/gemm_s8_neondot.o > /tmp/gemm_s8_neondot.s
  python3 bench/tools/count_loop_insns.py /tmp/gemm_s8_neondot.s
"""
import argparse
import collections
import re
import subprocess
import tempfile

MACS = ("sdot", "vpdpbusd", "vpmaddwd")
# Multiply-accumulates of one instruction on a 128-bit vector (sdot: 4 lanes x 4 bytes).
MACS_PER_INSN = {"sdot": 16}


def mca_cycles(body, cpu, triple):
    """llvm-mca's projected cycles per iteration of the loop `body` (its own branch dropped)."""
    lines = []
    for _, op, operands, _ in body[:-1]:
        operands = re.sub(r"\s*//.*$", "", operands)
        lines.append(f"{op} {operands}".strip())
    with tempfile.NamedTemporaryFile("w", suffix=".s") as f:
        f.write("\n".join(lines) + "\n")
        f.flush()
        out = subprocess.run(["llvm-mca", f"-mtriple={triple}", f"-mcpu={cpu}", "-iterations=200", f.name],
                             capture_output=True, text=True, check=True).stdout
    total = int(re.search(r"Total Cycles:\s+(\d+)", out).group(1))
    return total / 200.0
NOT_BRANCHES = {"bl", "blr", "br", "bic", "bif", "bit", "bsl", "bfi", "bfxil"}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("disassembly")
    ap.add_argument("--min-mac", type=int, default=16)
    ap.add_argument("--mca", metavar="CPU", help="project each loop with llvm-mca for this core")
    ap.add_argument("--triple", default="aarch64-linux-gnu")
    ap.add_argument("--peak-macs", type=float, default=32.0, help="the core's MACs per cycle")
    args = ap.parse_args()
    insns, func = [], None
    for line in open(args.disassembly):
        m = re.match(r"^[0-9a-f]+ <(.*)>:$", line)
        if m:
            func = m.group(1)
            continue
        m = re.match(r"^\s+([0-9a-f]+):\s+(\S+)\s*(.*)$", line)
        if m:
            insns.append((int(m.group(1), 16), m.group(2), m.group(3), func))
    index = {a: i for i, (a, _, _, _) in enumerate(insns)}
    for i, (addr, op, operands, fn) in enumerate(insns):
        if not (op.startswith("b") or op.startswith("j")) or op in NOT_BRANCHES:
            continue
        m = re.search(r"\b([0-9a-f]+) <", operands)
        if not m or int(m.group(1), 16) > addr or int(m.group(1), 16) not in index:
            continue
        body = insns[index[int(m.group(1), 16)]: i + 1]
        mix = collections.Counter(x[1] for x in body)
        macs = sum(mix[k] for k in MACS)
        # Only innermost loops: no other backward branch inside.
        if macs < args.min_mac or any(x[1].startswith(("b", "j")) and x[1] not in NOT_BRANCHES for x in body[:-1]):
            continue
        print(f"{fn[:90]}\n  loop {body[0][0]:x}..{addr:x}: {len(body)} instructions, {macs} MAC: "
              + ", ".join(f"{k} {v}" for k, v in mix.most_common()))
        if args.mca:
            cycles = mca_cycles(body, args.mca, args.triple)
            mac_ops = sum(mix[k] * MACS_PER_INSN.get(k, 0) for k in MACS)
            share = 100.0 * mac_ops / (cycles * args.peak_macs) if mac_ops else 0.0
            print(f"  llvm-mca {args.mca}: {cycles:.1f} cycles per iteration, {mac_ops} MACs: {share:.0f} % of peak")


if __name__ == "__main__":
    main()
