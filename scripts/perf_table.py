#!/usr/bin/env python3
"""Print the numbers table (markdown) from act_bench and act_kernel_bench JSON files.

    scripts/perf_table.py [--label TEXT] [--note TEXT] FILE... [--label TEXT FILE...]

Each FILE is one of:
  - `act_bench --json` output (one object with "latency_ms" and "peak"), or a JSON list of such
    objects. A record may carry "machine_label" (the column it goes in), "note" (a footnote) and
    "estimate": true (a projection, not a measurement: its cell says so);
  - `act_kernel_bench --benchmark_format=json` output (an object with "benchmarks" and "context").

A record's column is its "machine_label", else the last `--label TEXT` before its file, else its
machine.cpu_model. `--note TEXT` adds a footnote to the cells of the files after it (until the next
--note) that carry no "note" of their own.

act_bench records become one table: a row per model, precision and thread count, a column per
machine, each cell the p50 latency and its share of the peak the same run measured
(peak.percent_of_peak_p50). Kernel benchmarks become a second table: time, GMAC/s and % of peak,
by thread CPU time where the benchmark reports it (one thread). Python 3 standard library only.
"""

import json
import re
import sys


def load(path):
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def is_bench_record(obj):
    return isinstance(obj, dict) and "latency_ms" in obj and "peak" in obj


def is_kernel_report(obj):
    return isinstance(obj, dict) and "benchmarks" in obj and "context" in obj


def model_label(rec):
    model = rec.get("model", {})
    name = model.get("name", "?")
    m = re.match(r'built-in "([^"]+)"', name)
    if m:
        name = m.group(1)
    cameras = model.get("config", {}).get("cameras", [])
    if cameras:
        sizes = ",".join("%dx%d" % (c["height"], c["width"]) for c in cameras)
        name = "%s %s" % (name, sizes)
    return name


def precision_label(rec):
    p = rec.get("model", {}).get("precision", "?")
    return p.split()[0].upper()


def machine_label(rec, label):
    if rec.get("machine_label"):
        return rec["machine_label"]
    if label:
        return label
    machine = rec.get("machine", {})
    text = machine.get("cpu_model", "unknown machine")
    if machine.get("online_cores"):
        text += ", %d cores" % machine["online_cores"]
    if machine.get("emulated") or rec.get("emulated"):
        text += " (EMULATED)"
    return text


def fmt_ms(ms):
    if ms >= 100:
        return "%.0f" % ms
    if ms >= 10:
        return "%.1f" % ms
    return "%.2f" % ms


class Table:
    def __init__(self):
        self.machines = []  # column order: first seen
        self.cells = {}  # (model, precision, threads) -> {machine: text}
        self.notes = []

    def add(self, rec, label, note=None):
        machine = machine_label(rec, label)
        note = rec.get("note") or note
        if machine not in self.machines:
            self.machines.append(machine)
        threads = rec.get("engine", {}).get("threads", 0)
        key = (model_label(rec), precision_label(rec), threads)
        p50 = rec["latency_ms"]["total"]["p50"]
        pct = rec["peak"].get("percent_of_peak_p50")
        text = "%s ms" % fmt_ms(p50)
        if pct:
            text += " (%.0f %%)" % pct
        if rec.get("estimate"):
            text = "~%.0f ms, **estimate**" % p50
        if note:
            if note not in self.notes:
                self.notes.append(note)
            text += " [%d]" % (self.notes.index(note) + 1)
        self.cells.setdefault(key, {})[machine] = text

    def markdown(self):
        def order(key):
            model, precision, threads = key
            rank = {"default": 0, "rover": 1}.get(model.split()[0], 2)
            return (rank, model, precision != "INT8", threads)

        lines = ["| model | precision | threads | " + " | ".join(self.machines) + " |",
                 "|---|---|---|" + "---|" * len(self.machines)]
        for key in sorted(self.cells, key=order):
            row = self.cells[key]
            lines.append("| %s | %s | %d | " % key + " | ".join(row.get(m, "-") for m in self.machines) + " |")
        lines.append("")
        lines.append("p50 latency of one inference (`act_bench`, whole model), and in parentheses its share of the")
        lines.append("peak that run measured on as many threads (INT8: `vpdpbusd`/`sdot` probe; FP32: FMA probe).")
        for i, note in enumerate(self.notes):
            lines.append("")
            lines.append("[%d] %s" % (i + 1, note))
        return "\n".join(lines)


def kernel_table(reports):
    lines = ["| benchmark | machine | ms | GMAC/s | % of peak | 2-thread speed-up |", "|---|---|---|---|---|---|"]
    for report, label in reports:
        ctx = report["context"]
        machine = label or "%s, %s cores" % (ctx.get("cpu_model", "?"), ctx.get("num_cpus", "?"))
        for b in report["benchmarks"]:
            if b.get("run_type") == "aggregate" and b.get("aggregate_name") != "median":
                continue
            name = b.get("run_name", b["name"]) if b.get("run_type") == "aggregate" else b["name"]
            name = name.replace("/real_time", "")
            scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
            ms = b["real_time"] * scale
            gmacs = b.get("GMAC/s_cpu", b.get("GMAC/s"))
            pct = b.get("pct_peak_cpu", b.get("pct_peak"))
            speedup = b.get("speedup_vs_1t")
            lines.append("| `%s` | %s | %s | %s | %s | %s |" % (
                name, machine, "%.3f" % ms, "%.0f" % gmacs if gmacs else "-",
                "%.0f %%" % pct if pct else "-", "%.2fx" % speedup if speedup else "-"))
    lines.append("")
    lines.append("ms is wall time; GMAC/s and % of peak are by the thread's CPU time for one-thread rows (wall time")
    lines.append("otherwise), against the register-only probe of the same run.")
    for report, label in reports:
        ctx = report["context"]
        probes = ["`%s` %.0f" % (k[len("peak_"):-len("_GMACps")], float(v)) for k, v in sorted(ctx.items())
                  if k.startswith("peak_") and k.endswith("_GMACps")]
        if probes:
            machine = label or ctx.get("cpu_model", "?")
            lines.append("Probes on %s, one thread, GMAC/s: %s." % (machine, ", ".join(probes)))
    return "\n".join(lines)


def main(argv):
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        return 0 if argv else 2
    table, kernels, label, note, i = Table(), [], None, None, 0
    while i < len(argv):
        arg = argv[i]
        if arg in ("--label", "--note"):
            if i + 1 >= len(argv):
                print("perf_table.py: %s needs a value" % arg, file=sys.stderr)
                return 2
            if arg == "--label":
                label = argv[i + 1]
            else:
                note = argv[i + 1]
            i += 2
            continue
        try:
            obj = load(arg)
        except (OSError, ValueError) as e:
            print("perf_table.py: %s: %s" % (arg, e), file=sys.stderr)
            return 1
        records = obj if isinstance(obj, list) else [obj]
        if all(is_bench_record(r) for r in records):
            for r in records:
                table.add(r, label, note)
        elif is_kernel_report(obj):
            kernels.append((obj, label))
        else:
            print("perf_table.py: %s: neither act_bench --json nor act_kernel_bench --benchmark_format=json output"
                  % arg, file=sys.stderr)
            return 1
        i += 1
    out = []
    if table.cells:
        out.append(table.markdown())
    if kernels:
        out.append(kernel_table(kernels))
    print("\n\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
