// act_drive's live view in headless chromium, driven like a user would (test/drive/test_live_view.cc
// starts act_drive on a video with the pty fake Arduino and checks the serial line against the times
// written here). Usage: node drive_page.js URL TOKEN OUT.json
// Records what the page shows (frames, gauges, the chunk ahead) and when it clicked what (Date.now(),
// milliseconds since the epoch): e-stop, resume without and with the token, keyboard and stick driving.
'use strict';
const fs = require('fs');
const { withPage } = require('./browser');

const [url, token, out] = process.argv.slice(2);
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// A fingerprint of the image the page shows now (the MJPEG <img> drawn to a canvas).
const shownFrame = (page) => page.$eval('#frame', (img) => {
  const c = document.createElement('canvas');
  c.width = img.naturalWidth;
  c.height = img.naturalHeight;
  c.getContext('2d').drawImage(img, 0, 0);
  return c.toDataURL('image/png');
});

async function clickAndWaitForReply(page, selector) {
  await page.$eval('#message', (m) => { delete m.dataset.status; });
  await page.click(selector);
  await page.waitForFunction(() => document.getElementById('message').dataset.status, null, { timeout: 5000 });
  return Number(await page.$eval('#message', (m) => m.dataset.status));
}

withPage(async (page, external) => {
  const result = { external, manual_issued: [] };
  // The commands that move the car carry the time the page issued them on the server's clock.
  page.on('request', (r) => {
    if (r.url().includes('/manual')) result.manual_issued.push(r.headers()['x-act-issued'] || null);
  });
  await page.goto(url);
  await page.waitForFunction(() => document.getElementById('frame').naturalWidth > 0, null, { timeout: 15000 });
  result.image_width = await page.$eval('#frame', (img) => img.naturalWidth);
  // The policy drives: the frame, the gauges and the chunk ahead as the page shows them.
  const firstFrame = await shownFrame(page);
  result.samples = [];
  for (let i = 0; i < 15; ++i) {
    await sleep(100);
    result.samples.push(await page.evaluate(() => ({
      frame_index: Number(document.getElementById('frame-index').textContent),
      steering: Number(document.getElementById('steer-gauge').dataset.value),
      throttle: Number(document.getElementById('throttle-gauge').dataset.value),
      ahead_points: Number(document.getElementById('ahead').dataset.points || 0),
    })));
  }
  result.frame_changed = (await shownFrame(page)) !== firstFrame;

  result.estop_status = await clickAndWaitForReply(page, '#estop');
  result.t_estop = Number(await page.$eval('#estop', (b) => b.dataset.clickedAt));  // the page's own click time
  await sleep(1000);
  result.resume_without_token_status = await clickAndWaitForReply(page, '#resume');  // the token field is empty
  await sleep(500);
  await page.fill('#token', token);
  result.t_resume = Date.now();
  result.resume_status = await clickAndWaitForReply(page, '#resume');
  await sleep(1000);

  // Driving by keyboard overrides the policy; releasing the keys holds neutral until resumed.
  await page.click('#timings');  // focus leaves the token field
  await page.keyboard.down('ArrowRight');
  await page.keyboard.down('ArrowUp');
  result.t_keys_down = Date.now();
  await sleep(1000);
  result.t_keys_up = Date.now();
  await page.keyboard.up('ArrowRight');
  await page.keyboard.up('ArrowUp');
  await sleep(800);
  result.mode_text = await page.$eval('#mode-now', (e) => e.textContent);

  // The on-screen stick: full left, no throttle.
  const box = await (await page.$('#stick')).boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x - 20, box.y + box.height / 2);  // beyond the rim: clamped to -1
  result.t_stick_down = Date.now();
  await sleep(800);
  result.t_stick_up = Date.now();
  await page.mouse.up();
  await sleep(500);
  result.t_end = Date.now();
  fs.writeFileSync(out, JSON.stringify(result, null, 1));
}).catch((e) => {
  console.error(e);
  process.exit(1);
});
