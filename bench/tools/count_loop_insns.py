#!/usr/bin/env python3
"""Static instruction mix of the innermost loops of a disassembled kernel object.

Prints every loop (a backward branch and the instructions from its target to it) that holds at
least --min-mac multiply-accumulate instructions (sdot / vpdpbusd / vpmaddwd), with the count of
each mnemonic: the basis of the NEON %-of-peak estimate in kernels/README.md, where no A76 is at
hand to time the kernel (qemu-user executes it but does not model timing).

With --mca CPU each loop also goes through llvm-mca for that core: for the Raspberry Pi 5's
Cortex-A76, --mca neoverse-n1 with LLVM 19 (scripts/install_cross_deps.sh --projection). The N1 is
the A76's server twin (same pipelines); LLVM schedules -mcpu=cortex-a76 with its Cortex-A57 model
(FMLA at 1 per cycle and 10 cycles of latency against the A76's 2 and 4). The projected cycles per iteration and the share of the
core's MAC peak (--peak-macs per cycle; by default 32 for SDOT and 8 for FMLA on the A76's two
128-bit pipes) the loop can reach, a projection, not a measurement. With --min-mac 0 and --function
the loops of kernels without MACs (quantize, softmax, pooling) are projected too: cycles per iteration,
to be divided by the elements one iteration handles.

  aarch64-linux-gnu-g++ -std=c++20 -O3 -DNDEBUG -ffp-contract=off -march=armv8.2-a+dotprod -I. \
      -c kernels/gemm_s8/gemm_s8_neondot.cc -o /tmp/gemm_s8_neondot.o
  aarch64-linux-gnu-objdump -d --no-show-raw-insn -C /tmp/gemm_s8_neondot.o > /tmp/gemm_s8_neondot.s
  python3 bench/tools/count_loop_insns.py /tmp/gemm_s8_neondot.s
"""
import argparse
import collections
import re
import shutil
import subprocess
import tempfile

MACS = ("sdot", "vpdpbusd", "vpmaddwd", "fmla", "vfmadd")  # prefixes of mnemonics
# Multiply-accumulates of one instruction on a 128-bit vector (sdot: 4 lanes x 4 bytes; fmla: 4 floats).
MACS_PER_INSN = {"sdot": 16, "fmla": 4}
# The A76's MACs per cycle for each kind (two 128-bit ASIMD pipes): the default of --peak-macs.
PEAK_MACS_PER_CYCLE = {"sdot": 32.0, "fmla": 8.0}


def mca_cycles(body, cpu, triple, mca):
    """llvm-mca's projected cycles per iteration of the loop `body` (its own branch dropped)."""
    lines = []
    for _, op, operands, _ in body[:-1]:
        operands = re.sub(r"\s*//.*$", "", operands)
        lines.append(f"{op} {operands}".strip())
    with tempfile.NamedTemporaryFile("w", suffix=".s") as f:
        f.write("\n".join(lines) + "\n")
        f.flush()
        out = subprocess.run([mca, f"-mtriple={triple}", f"-mcpu={cpu}", "-iterations=200", f.name],
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
    ap.add_argument("--llvm-mca", default=shutil.which("llvm-mca-19") or "llvm-mca", help="the llvm-mca to run")
    ap.add_argument("--peak-macs", type=float, help="the core's MACs per cycle (default: by instruction, A76)")
    ap.add_argument("--function", default="", help="only loops of functions whose name matches this regex")
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
        macs = sum(v for k, v in mix.items() if k.startswith(MACS))
        # Only innermost loops: no other backward branch inside.
        if not re.search(args.function, fn or "") or macs < args.min_mac or any(x[1].startswith(("b", "j")) and x[1] not in NOT_BRANCHES for x in body[:-1]):
            continue
        print(f"{fn[:90]}\n  loop {body[0][0]:x}..{addr:x}: {len(body)} instructions, {macs} MAC: "
              + ", ".join(f"{k} {v}" for k, v in mix.most_common()))
        if args.mca and any(x[1] in ("bl", "blr", "ret", "call") for x in body):
            print("  (a call inside: not projected)")
        elif args.mca:
            try:
                cycles = mca_cycles(body, args.mca, args.triple, args.llvm_mca)
            except subprocess.CalledProcessError:
                print("  (llvm-mca could not read this loop: not projected)")
                continue
            mac_ops = sum(v * MACS_PER_INSN.get(k, 0) for k, v in mix.items())
            kind = next((k for k in mix if k.startswith(MACS)), None)
            peak = args.peak_macs or PEAK_MACS_PER_CYCLE.get(kind, 0.0)
            share = f": {100.0 * mac_ops / (cycles * peak):.0f} % of peak" if mac_ops and peak else ""
            print(f"  llvm-mca {args.mca}: {cycles:.1f} cycles per iteration, {mac_ops} MACs{share}")


if __name__ == "__main__":
    main()
