#!/usr/bin/env node
// Runs an ONNX model in ONNX Runtime (npm's onnxruntime-node, CPU) for actengine's export tests and
// the comparison in docs/onnx-and-hailo.md:
//   node run_onnx.js MODEL.onnx OUT_DIR [--threads N] [--repeat N] [--samples N] NAME=FILE.bin:D0xD1x... ...
// Each input is raw little-endian float32 with its shape; each output is written to
// OUT_DIR/<output name>.bin (raw float32). Prints one JSON line: the outputs' shapes and, over
// --repeat runs after one warm-up, the median and minimum run time in milliseconds.
// --samples N: each input file holds N inputs of its shape one after another, the model runs on
// each, and each output file holds the N outputs in that order (one process and one model load for
// a batch of observations: the load is most of a run's time).
'use strict';
const fs = require('fs');
const path = require('path');
const ort = require('onnxruntime-node');

function usage(message) {
  process.stderr.write(`run_onnx.js: ${message}\nusage: node run_onnx.js MODEL.onnx OUT_DIR [--threads N] [--repeat N] [--samples N] NAME=FILE.bin:D0xD1x...\n`);
  process.exit(2);
}

async function main() {
  const args = process.argv.slice(2);
  if (args.length < 2) usage('a model and an output folder are required');
  const [model, outDir] = args;
  let threads = 1;
  let repeat = 0;
  let samples = 1;
  const inputs = {};
  for (let i = 2; i < args.length; ++i) {
    if (args[i] === '--threads' || args[i] === '--repeat' || args[i] === '--samples') {
      const n = Number(args[++i]);
      if (!Number.isInteger(n) || n < 0) usage(`${args[i - 1]} needs a whole number`);
      if (args[i - 1] === '--threads') threads = n; else if (args[i - 1] === '--repeat') repeat = n; else samples = n;
      continue;
    }
    const m = /^(.+)=(.+):([0-9x]+)$/.exec(args[i]);
    if (!m) usage(`bad input "${args[i]}"`);
    const shape = m[3].split('x').map(Number);
    inputs[m[1]] = { file: m[2], dims: m[3], shape };
  }
  if (samples < 1) usage('--samples needs at least 1');
  // The feeds of each sample: its slice of every input file.
  const feeds = Array.from({ length: samples }, () => ({}));
  for (const [name, input] of Object.entries(inputs)) {
    const bytes = fs.readFileSync(input.file);
    const count = input.shape.reduce((a, b) => a * b, 1);
    if (bytes.length !== samples * count * 4) {
      usage(`${input.file} holds ${bytes.length} bytes, ${samples} of shape ${input.dims} need ${samples * count * 4}`);
    }
    const all = new Float32Array(bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.length));
    for (let s = 0; s < samples; ++s) {
      feeds[s][name] = new ort.Tensor('float32', all.slice(s * count, (s + 1) * count), input.shape);
    }
  }
  const session = await ort.InferenceSession.create(model, {
    intraOpNumThreads: threads, interOpNumThreads: 1, executionMode: 'sequential', graphOptimizationLevel: 'all',
  });
  const results = [];
  for (const sampleFeeds of feeds) results.push(await session.run(sampleFeeds));
  const times = [];
  for (let r = 0; r < repeat; ++r) {
    const start = process.hrtime.bigint();
    await session.run(feeds[0]);
    times.push(Number(process.hrtime.bigint() - start) / 1e6);
  }
  fs.mkdirSync(outDir, { recursive: true });
  const outputs = {};
  for (const name of session.outputNames) {
    const samplesOut = results.map((r) => Buffer.from(r[name].data.buffer, r[name].data.byteOffset, r[name].data.byteLength));
    fs.writeFileSync(path.join(outDir, `${name}.bin`), Buffer.concat(samplesOut));
    outputs[name] = results[0][name].dims;
  }
  times.sort((a, b) => a - b);
  const report = { outputs, threads, runs: repeat };
  if (repeat > 0) Object.assign(report, { median_ms: times[Math.floor(repeat / 2)], min_ms: times[0] });
  process.stdout.write(JSON.stringify(report) + '\n');
}

main().catch((e) => { process.stderr.write(`run_onnx.js: ${e.message}\n`); process.exit(1); });
