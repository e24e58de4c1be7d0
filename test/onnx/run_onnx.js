#!/usr/bin/env node
// Runs an ONNX model in ONNX Runtime (npm's onnxruntime-node, CPU) for actengine's export tests and
// the README's comparison:
//   node run_onnx.js MODEL.onnx OUT_DIR [--threads N] [--repeat N] NAME=FILE.bin:D0xD1x... ...
// Each input is raw little-endian float32 with its shape; each output is written to
// OUT_DIR/<output name>.bin (raw float32). Prints one JSON line: the outputs' shapes and, over
// --repeat runs after one warm-up, the median and minimum run time in milliseconds.
'use strict';
const fs = require('fs');
const path = require('path');
const ort = require('onnxruntime-node');

function usage(message) {
  process.stderr.write(`run_onnx.js: ${message}\nusage: node run_onnx.js MODEL.onnx OUT_DIR [--threads N] [--repeat N] NAME=FILE.bin:D0xD1x...\n`);
  process.exit(2);
}

async function main() {
  const args = process.argv.slice(2);
  if (args.length < 2) usage('a model and an output folder are required');
  const [model, outDir] = args;
  let threads = 1;
  let repeat = 0;
  const feeds = {};
  for (let i = 2; i < args.length; ++i) {
    if (args[i] === '--threads' || args[i] === '--repeat') {
      const n = Number(args[++i]);
      if (!Number.isInteger(n) || n < 0) usage(`${args[i - 1]} needs a whole number`);
      if (args[i - 1] === '--threads') threads = n; else repeat = n;
      continue;
    }
    const m = /^(.+)=(.+):([0-9x]+)$/.exec(args[i]);
    if (!m) usage(`bad input "${args[i]}"`);
    const shape = m[3].split('x').map(Number);
    const bytes = fs.readFileSync(m[2]);
    const count = shape.reduce((a, b) => a * b, 1);
    if (bytes.length !== count * 4) usage(`${m[2]} holds ${bytes.length} bytes, shape ${m[3]} needs ${count * 4}`);
    const data = new Float32Array(bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.length));
    feeds[m[1]] = new ort.Tensor('float32', data, shape);
  }
  const session = await ort.InferenceSession.create(model, {
    intraOpNumThreads: threads, interOpNumThreads: 1, executionMode: 'sequential', graphOptimizationLevel: 'all',
  });
  let results = await session.run(feeds);
  const times = [];
  for (let r = 0; r < repeat; ++r) {
    const start = process.hrtime.bigint();
    results = await session.run(feeds);
    times.push(Number(process.hrtime.bigint() - start) / 1e6);
  }
  fs.mkdirSync(outDir, { recursive: true });
  const outputs = {};
  for (const name of session.outputNames) {
    const t = results[name];
    fs.writeFileSync(path.join(outDir, `${name}.bin`), Buffer.from(t.data.buffer, t.data.byteOffset, t.data.byteLength));
    outputs[name] = t.dims;
  }
  times.sort((a, b) => a - b);
  const report = { outputs, threads, runs: repeat };
  if (repeat > 0) Object.assign(report, { median_ms: times[Math.floor(repeat / 2)], min_ms: times[0] });
  process.stdout.write(JSON.stringify(report) + '\n');
}

main().catch((e) => { process.stderr.write(`run_onnx.js: ${e.message}\n`); process.exit(1); });
