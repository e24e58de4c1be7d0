// act_drive's live view page (live_view.h): everything inline, nothing fetched from elsewhere.
#include "apps/drive/live_view.h"

namespace act::drive {

const char* const kLiveViewPage = R"html(<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>act_drive</title>
<style>
body { font: 14px sans-serif; margin: 12px; background: #111; color: #ddd; }
.row { display: flex; gap: 16px; flex-wrap: wrap; align-items: flex-start; }
#frame { width: 384px; image-rendering: pixelated; background: #000; border: 1px solid #444; }
.gauge { position: relative; width: 300px; height: 22px; background: #333; margin: 4px 0 10px; }
.gauge .zero { position: absolute; left: 50%; top: 0; bottom: 0; width: 1px; background: #888; }
.gauge .mark { position: absolute; top: 0; bottom: 0; width: 6px; margin-left: -3px; background: #4cf; }
#ahead { background: #222; border: 1px solid #444; }
#estop { font-size: 28px; font-weight: bold; color: #fff; background: #c00; border: 3px solid #f66; padding: 14px 28px; }
#stick { width: 160px; height: 160px; border-radius: 50%; background: #333; position: relative; touch-action: none; }
#knob { width: 40px; height: 40px; border-radius: 50%; background: #888; position: absolute; left: 60px; top: 60px; }
.fault { color: #f66; font-weight: bold; }
button, select, input { font-size: 14px; margin: 2px; }
</style></head><body>
<div class="row">
  <div><img id="frame" src="/stream.mjpg" alt="the model's view"><div>frame <span id="frame-index">-</span></div></div>
  <div>
    <button id="estop">E-STOP</button>
    <div>mode <b id="mode-now">-</b>, driving: <b id="driver">-</b></div>
    <div>fault: <span id="fault" class="fault"></span></div>
    <div>steering <span id="steer-text"></span><div class="gauge" id="steer-gauge" data-value="0"><div class="zero"></div><div class="mark"></div></div></div>
    <div>throttle <span id="throttle-text"></span><div class="gauge" id="throttle-gauge" data-value="0"><div class="zero"></div><div class="mark"></div></div></div>
    <div>the chunk ahead (steering blue, throttle orange)</div>
    <canvas id="ahead" width="300" height="100"></canvas>
    <pre id="timings"></pre>
  </div>
  <div>
    <div>token <input id="token" size="18" placeholder="printed by act_drive"></div>
    <button id="resume">Resume</button>
    <select id="mode"><option>ai</option><option>manual</option><option>ai-steer</option></select>
    <button id="set-mode">Set mode</button>
    <div id="message"></div>
    <p>Drive by hand: drag the stick, or arrow keys / WASD. Any input overrides the AI until Resume.</p>
    <div id="stick"><div id="knob"></div></div>
  </div>
</div>
<script>
'use strict';
const $ = (id) => document.getElementById(id);
// The server's clock as this page sees it, from the fastest /stats round trip of the last 20: each
// command carries the time it was issued on that clock, and the server refuses one that arrives late.
const clockSamples = [];
function serverNow() {
  if (clockSamples.length === 0) return null;
  const best = clockSamples.reduce((a, b) => (b.rtt < a.rtt ? b : a));
  return performance.now() + best.offset;
}
function post(path, withToken) {
  const headers = withToken ? { 'X-Act-Token': $('token').value } : {};
  const issued = serverNow();
  if (withToken && issued !== null) headers['X-Act-Issued'] = issued.toFixed(1);
  return fetch(path, { method: 'POST', headers }).then(async (r) => {
    const body = await r.json().catch(() => ({}));
    $('message').textContent = r.ok ? (body.ok || 'ok') : 'refused: ' + (body.error || r.status);
    $('message').dataset.status = r.status;
    return r.status;
  });
}
$('estop').onclick = () => { $('estop').dataset.clickedAt = Date.now(); post('/estop', false); };
$('resume').onclick = () => post('/resume', true);
$('set-mode').onclick = () => post('/mode?mode=' + $('mode').value, true);

function setGauge(id, value) {
  const g = $(id);
  g.dataset.value = value.toFixed(3);
  g.querySelector('.mark').style.left = (50 + 50 * Math.max(-1, Math.min(1, value))) + '%';
}
function drawAhead(s) {
  const c = $('ahead'), ctx = c.getContext('2d');
  ctx.clearRect(0, 0, c.width, c.height);
  ctx.strokeStyle = '#555'; ctx.beginPath(); ctx.moveTo(0, c.height / 2); ctx.lineTo(c.width, c.height / 2); ctx.stroke();
  const n = Math.max(s.steering_ahead.length, 1);
  for (const [values, colour] of [[s.steering_ahead, '#4cf'], [s.throttle_ahead, '#f93']]) {
    ctx.strokeStyle = colour; ctx.beginPath();
    values.forEach((v, i) => {
      const x = i * c.width / n, y = c.height / 2 - v * c.height / 2;
      if (i === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
    });
    ctx.stroke();
  }
  c.dataset.points = s.steering_ahead.length;
}
async function refresh() {
  try {
    const t0 = performance.now();
    const r = await fetch('/stats');
    const t1 = performance.now();
    const s = await r.json();
    clockSamples.push({ offset: s.server_ms - (t0 + t1) / 2, rtt: t1 - t0 });
    if (clockSamples.length > 20) clockSamples.shift();
    $('frame-index').textContent = s.frame_index;
    $('mode-now').textContent = s.mode + (s.overridden ? ' (overridden by hand)' : '');
    $('driver').textContent = s.driver;
    $('fault').textContent = s.fault;
    setGauge('steer-gauge', s.steering);
    setGauge('throttle-gauge', s.throttle);
    $('steer-text').textContent = s.steering_us + ' us';
    $('throttle-text').textContent = s.throttle_us + ' us';
    drawAhead(s);
    $('timings').textContent = 'tick ' + s.tick + ' at ' + s.control_hz + ' Hz, jitter ' + s.jitter_ms.toFixed(1) +
      ' ms\ninference ' + s.infer_ms.toFixed(1) + ' ms, preprocess ' + s.preprocess_ms.toFixed(1) +
      ' ms, frame age ' + s.capture_age_ms.toFixed(0) + ' ms\n' + s.inferences + ' inferences, ' + s.overruns + ' overruns';
  } catch (e) {
    $('fault').textContent = 'act_drive does not answer';
  }
}
setInterval(refresh, 100);

// Driving by hand: the stick or the keys; sent 10 times a second while held, centre once on release.
const manual = { steering: 0, throttle: 0, stick: false };
const keys = new Set();
function keyInput() {
  const on = (a, b) => keys.has(a) || keys.has(b);
  return { steering: (on('ArrowRight', 'd') ? 1 : 0) - (on('ArrowLeft', 'a') ? 1 : 0),
           throttle: (on('ArrowUp', 'w') ? 1 : 0) - (on('ArrowDown', 's') ? 1 : 0) };
}
let driving = false;
function sendManual() {
  const active = manual.stick || keys.size > 0;
  if (!active && !driving) return;
  driving = active;
  const input = manual.stick ? manual : (keys.size > 0 ? keyInput() : { steering: 0, throttle: 0 });
  post('/manual?steering=' + input.steering.toFixed(3) + '&throttle=' + input.throttle.toFixed(3), true);
}
setInterval(sendManual, 100);
const driveKeys = ['ArrowUp', 'ArrowDown', 'ArrowLeft', 'ArrowRight', 'w', 'a', 's', 'd'];
document.addEventListener('keydown', (e) => {
  if (e.target.tagName === 'INPUT' || !driveKeys.includes(e.key)) return;
  e.preventDefault();
  if (!keys.has(e.key)) { keys.add(e.key); sendManual(); }
});
document.addEventListener('keyup', (e) => { keys.delete(e.key); if (keys.size === 0) sendManual(); });
const stick = $('stick'), knob = $('knob');
function moveStick(e) {
  const r = stick.getBoundingClientRect();
  const x = Math.max(-1, Math.min(1, (e.clientX - r.left - r.width / 2) / (r.width / 2)));
  const y = Math.max(-1, Math.min(1, (r.top + r.height / 2 - e.clientY) / (r.height / 2)));
  manual.steering = x; manual.throttle = y;
  knob.style.left = (60 + 60 * x) + 'px'; knob.style.top = (60 - 60 * y) + 'px';
}
stick.addEventListener('pointerdown', (e) => { manual.stick = true; stick.setPointerCapture(e.pointerId); moveStick(e); sendManual(); });
stick.addEventListener('pointermove', (e) => { if (manual.stick) moveStick(e); });
stick.addEventListener('pointerup', () => {
  manual.stick = false; manual.steering = 0; manual.throttle = 0;
  knob.style.left = '60px'; knob.style.top = '60px'; sendManual();
});
</script></body></html>
)html";

}  // namespace act::drive
