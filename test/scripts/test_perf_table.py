#!/usr/bin/env python3
"""scripts/perf_table.py on small act_bench --json and act_kernel_bench --benchmark_format=json samples
(data/: real outputs of this project's programs, trimmed). Standard library only; CTest perf_table_script."""

import json
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPT = os.path.join(HERE, "..", "..", "scripts", "perf_table.py")
DATA = os.path.join(HERE, "data")
ROVER_INT8 = os.path.join(DATA, "act_bench_rover_int8_2t.json")
DEFAULT_FP32 = os.path.join(DATA, "act_bench_default_fp32_1t.json")
KERNELS = os.path.join(DATA, "act_kernel_bench_sample.json")


def run(*args):
    p = subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True)
    return p.returncode, p.stdout, p.stderr


def row(out, prefix):
    rows = [line for line in out.splitlines() if line.startswith(prefix)]
    if len(rows) != 1:
        raise AssertionError("expected one row starting %r in:\n%s" % (prefix, out))
    return [cell.strip() for cell in rows[0].strip("|").split("|")]


class PerfTable(unittest.TestCase):
    def test_act_bench_rows_cells_and_label(self):
        code, out, err = run("--label", "test machine", ROVER_INT8, DEFAULT_FP32)
        self.assertEqual(code, 0, err)
        self.assertIn("| model | precision | threads | test machine |", out)
        # p50 87.316 ms at 20.37 % of the peak; 555.71 ms at 35.16 %
        self.assertEqual(row(out, "| rover 360x640 | INT8 | 2 |")[3], "87.3 ms (20 %)")
        self.assertEqual(row(out, "| default 480x640 | FP32 | 1 |")[3], "556 ms (35 %)")
        # default before rover
        self.assertLess(out.index("| default 480x640"), out.index("| rover 360x640"))

    def test_machine_from_the_json_without_a_label(self):
        code, out, _ = run(ROVER_INT8)
        self.assertEqual(code, 0)
        self.assertIn("| Intel(R) Xeon(R) Processor, 2 cores |", out)

    def test_records_with_their_own_label_note_and_estimate(self):
        records = [
            {"model": {"name": 'built-in "rover"', "precision": "int8 static",
                       "config": {"cameras": [{"height": 360, "width": 640}]}},
             "engine": {"threads": 4}, "latency_ms": {"total": {"p50": 55.0}},
             "peak": {"percent_of_peak_p50": None}, "machine_label": "Pi", "note": "projected", "estimate": True}]
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
            json.dump(records, f)
        try:
            code, out, err = run("--label", "other", ROVER_INT8, f.name)
        finally:
            os.unlink(f.name)
        self.assertEqual(code, 0, err)
        cells = row(out, "| rover 360x640 | INT8 | 4 |")
        self.assertEqual(cells[3:], ["-", "~55 ms, **estimate** [1]"])
        self.assertIn("[1] projected", out)

    def test_kernel_table_takes_the_median_and_cpu_time(self):
        code, out, err = run(KERNELS)
        self.assertEqual(code, 0, err)
        one = row(out, "| `gemm_s8/avx512vnni/enc_ffn1/threads:1` | Intel(R) Xeon(R) Processor, 2 cores | 3.851")
        self.assertEqual(one[3:5], ["298", "78 %"])  # GMAC/s_cpu and pct_peak_cpu, not wall time's
        median = row(out, "| `gemm_s8/avx512vnni/enc_ffn1/threads:1` | Intel(R) Xeon(R) Processor, 2 cores | 3.500")
        self.assertEqual(len(median), 6)
        self.assertNotIn("9.900", out)  # the mean aggregate is left out
        self.assertIn("0.44x", row(out, "| `gemm_s8/avx512vnni/enc_ffn1/threads:2`")[5])
        self.assertIn("`vpdpbusd_zmm` 383", out)  # the probes of the run, from its context

    def test_unknown_json_and_missing_files_fail(self):
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
            json.dump({"something": 1}, f)
        try:
            code, _, err = run(f.name)
        finally:
            os.unlink(f.name)
        self.assertEqual(code, 1)
        self.assertIn("neither act_bench", err)
        code, _, err = run(os.path.join(DATA, "no_such_file.json"))
        self.assertEqual(code, 1)


if __name__ == "__main__":
    unittest.main()
