#!/usr/bin/env node
// Latency of an ONNX model in ONNX Runtime (npm's onnxruntime-node, CPU), the counterpart of
// act_bench for our ONNX exports (act_convert --export-onnx; an INT8 blob exports QDQ):
//   node bench/tools/ort_bench.js MODEL.onnx [--threads T] [--warmup W] [--runs N] [--json FILE] [--profile]
// The inputs take the shapes the session's input metadata gives (our exports' shapes are static),
// filled with fixed pseudo-random values in [0, 1) (images in [0, 1], as act_bench's synthetic
// observations). T is ONNX Runtime's intra-op thread count (inter-op 1, sequential, all graph
// optimizations). After W untimed runs, N timed runs; prints mean, p50 and p99 in ms
// (percentiles interpolated between order statistics, as act_bench's) and, with --json, writes
// them with the model, threads and ONNX Runtime's version. --profile: after the timed runs, a second
// session with ONNX Runtime's profiler runs the model 3 times and the time per run by op type
// prints (and goes in the JSON as op_types_ms): which ops ONNX Runtime ran, e.g. whether a QDQ
// model's convolutions and GEMMs became QLinearConv / MatMulInteger or stayed float beside
// DequantizeLinear. The profiled runs are not the timed ones.
// onnxruntime-node comes from test/onnx/node_modules (scripts/install_node_deps.sh).
'use strict';
const fs = require('fs');
const os = require('os');
const path = require('path');

function usage(message) {
  process.stderr.write(`ort_bench.js: ${message}\n` +
    'usage: node ort_bench.js MODEL.onnx [--threads T] [--warmup W] [--runs N] [--json FILE] [--profile]\n');
  process.exit(2);
}

function loadOrt() {
  const dir = path.join(__dirname, '..', '..', 'test', 'onnx');
  try {
    return require(require.resolve('onnxruntime-node', { paths: [dir] }));
  } catch (e) {
    process.stderr.write(`ort_bench.js: onnxruntime-node is not installed in ${dir}/node_modules ` +
      `(run scripts/install_node_deps.sh): ${e.message}\n`);
    process.exit(1);
  }
}

function parseArgs(args) {
  const opt = { model: '', threads: 1, warmup: 2, runs: 20, json: '', profile: false };
  const counts = { '--threads': 'threads', '--warmup': 'warmup', '--runs': 'runs' };
  for (let i = 0; i < args.length; ++i) {
    const a = args[i];
    if (a === '-h' || a === '--help') usage('help');
    if (a in counts) {
      const n = Number(args[++i]);
      if (!Number.isInteger(n) || n < 0) usage(`${a} needs a whole number, not "${args[i]}"`);
      opt[counts[a]] = n;
    } else if (a === '--profile') {
      opt.profile = true;
    } else if (a === '--json') {
      if (i + 1 >= args.length) usage('--json needs a file');
      opt.json = args[++i];
    } else if (a.startsWith('-')) {
      usage(`unknown option ${a}`);
    } else if (!opt.model) {
      opt.model = a;
    } else {
      usage(`one model only (got "${opt.model}" and "${a}")`);
    }
  }
  if (!opt.model) usage('a model (.onnx) is required');
  if (!fs.existsSync(opt.model)) usage(`no file ${opt.model}`);
  if (opt.threads < 1) usage('--threads needs at least 1');
  if (opt.runs < 1) usage('--runs needs at least 1');
  return opt;
}

// Feeds of the session's input shapes, filled by a fixed linear congruential sequence.
function makeFeeds(ort, session) {
  let state = 12345;
  const next = () => { state = (Math.imul(state, 1103515245) + 12345) >>> 0; return state / 4294967296; };
  const feeds = {};
  for (const meta of session.inputMetadata) {
    if (!meta.isTensor || meta.type !== 'float32') {
      throw new Error(`input ${meta.name} is ${meta.isTensor ? meta.type : 'not a tensor'}; only float32 inputs are fed`);
    }
    const dims = meta.shape.map((d) => {
      if (!Number.isInteger(d) || d < 1) throw new Error(`input ${meta.name} has a dimension "${d}" that is not fixed`);
      return d;
    });
    const data = new Float32Array(dims.reduce((a, b) => a * b, 1));
    for (let i = 0; i < data.length; ++i) data[i] = next();
    feeds[meta.name] = new ort.Tensor('float32', data, dims);
  }
  return feeds;
}

function percentile(sorted, q) {
  const pos = (sorted.length - 1) * q;
  const lo = Math.floor(pos);
  const hi = Math.min(lo + 1, sorted.length - 1);
  return sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo);
}

const kProfiledRuns = 3;

// Time per run by op type, from ONNX Runtime's profiler (its file is read, then removed).
async function profileOpTypes(ort, opt, sessionOptions) {
  const prefix = path.join(fs.mkdtempSync(path.join(os.tmpdir(), 'ort_bench-')), 'profile');
  const dir = path.dirname(prefix);
  const session = await ort.InferenceSession.create(opt.model, { ...sessionOptions, enableProfiling: true, profileFilePrefix: prefix });
  const feeds = makeFeeds(ort, session);
  for (let i = 0; i <= kProfiledRuns; ++i) await session.run(feeds);  // a warm-up run, then the profiled ones
  session.endProfiling();
  const files = fs.readdirSync(dir);
  if (files.length !== 1) throw new Error(`ONNX Runtime's profiler wrote ${files.length} files in ${dir}, not one`);
  const events = JSON.parse(fs.readFileSync(path.join(dir, files[0]), 'utf8'));
  fs.rmSync(dir, { recursive: true, force: true });
  // The last kProfiledRuns runs' kernel times (the profile's first run is a warm-up).
  const runs = events.filter((e) => e.cat === 'Session' && e.name === 'model_run');
  const from = runs.length > kProfiledRuns ? runs[runs.length - kProfiledRuns].ts : 0;
  const byType = {};
  for (const e of events) {
    if (e.cat !== 'Node' || !e.name.endsWith('_kernel_time') || e.ts < from) continue;
    byType[e.args.op_name] = (byType[e.args.op_name] || 0) + e.dur / 1000 / kProfiledRuns;
  }
  return Object.fromEntries(Object.entries(byType).sort((a, b) => b[1] - a[1]));
}

async function main() {
  const opt = parseArgs(process.argv.slice(2));
  const ort = loadOrt();
  const sessionOptions = {
    intraOpNumThreads: opt.threads, interOpNumThreads: 1, executionMode: 'sequential', graphOptimizationLevel: 'all',
  };
  const session = await ort.InferenceSession.create(opt.model, sessionOptions);
  const feeds = makeFeeds(ort, session);
  for (let i = 0; i < opt.warmup; ++i) await session.run(feeds);
  const times = [];
  for (let i = 0; i < opt.runs; ++i) {
    const start = process.hrtime.bigint();
    await session.run(feeds);
    times.push(Number(process.hrtime.bigint() - start) / 1e6);
  }
  const sorted = [...times].sort((a, b) => a - b);
  const latency = {
    count: times.length, mean: times.reduce((a, b) => a + b, 0) / times.length, min: sorted[0],
    p50: percentile(sorted, 0.5), p90: percentile(sorted, 0.9), p99: percentile(sorted, 0.99), max: sorted[sorted.length - 1],
  };
  const inputs = Object.fromEntries(session.inputMetadata.map((m) => [m.name, m.shape]));
  process.stdout.write(`model        ${opt.model}\nruntime      onnxruntime-node ${ort.env.versions.node || ''}, ` +
    `intra-op threads ${opt.threads}\ninputs       ${JSON.stringify(inputs)}\n` +
    `latency      mean ${latency.mean.toFixed(2)} ms, p50 ${latency.p50.toFixed(2)} ms, ` +
    `p99 ${latency.p99.toFixed(2)} ms (${opt.runs} runs after ${opt.warmup} warm-up)\n`);
  const opTypes = opt.profile ? await profileOpTypes(ort, opt, sessionOptions) : null;
  if (opTypes) {
    process.stdout.write(`op types     ms per run (profiled, ${kProfiledRuns} runs):\n`);
    for (const [type, ms] of Object.entries(opTypes).slice(0, 12)) {
      process.stdout.write(`  ${type.padEnd(24)} ${ms.toFixed(2).padStart(9)}\n`);
    }
  }
  if (opt.json) {
    const report = {
      model: opt.model, runtime: 'onnxruntime-node', ort_version: ort.env.versions.node || null,
      threads: opt.threads, warmup_runs: opt.warmup, inputs, latency_ms: latency, runs_ms: times,
    };
    if (opTypes) report.op_types_ms = opTypes;
    fs.writeFileSync(opt.json, JSON.stringify(report, null, 2) + '\n');
  }
}

main().catch((e) => { process.stderr.write(`ort_bench.js: error: ${e.message}\n`); process.exit(1); });
