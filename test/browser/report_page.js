// Opens act_eval's / act_convert's HTML report in headless chromium and checks that a person would
// see charts: each chart region of a full-page screenshot has non-blank pixels, and the page requested
// nothing from the network and names no external URL. Data are drawn in colour (axes and labels in
// grey and black), so a region counts as drawn when it has coloured pixels.
//   node report_page.js REPORT.html [SCREENSHOT.png]
// Prints one line per chart and exits 1 on any failure.
'use strict';
const fs = require('fs');
const path = require('path');
const { withPage } = require('./browser');

async function main() {
  const report = path.resolve(process.argv[2]);
  const screenshotPath = process.argv[3];
  const html = fs.readFileSync(report, 'utf8');
  const failures = [];
  const urls = html.match(/(https?:)?\/\/[a-z0-9.-]+\.[a-z]{2,}[^\s'"<>]*/gi) || [];
  if (urls.length) failures.push('the file names external URLs: ' + urls.join(', '));

  await withPage(async (page, external) => {
    await page.goto('file://' + report, { waitUntil: 'load' });
    const shot = await page.screenshot({ fullPage: true });
    if (screenshotPath) fs.writeFileSync(screenshotPath, shot);
    const charts = await page.$$eval('svg.chart', (svgs) => svgs.map((s) => {
      const r = s.getBoundingClientRect();
      return { cls: s.getAttribute('class'), x: r.left + window.scrollX, y: r.top + window.scrollY, w: r.width, h: r.height };
    }));
    if (charts.length === 0) failures.push('no chart on the page');
    // Count, in the screenshot itself, the coloured pixels of each chart region.
    const counts = await page.evaluate(async ({ png, regions }) => {
      const image = new Image();
      image.src = 'data:image/png;base64,' + png;
      await image.decode();
      const canvas = document.createElement('canvas');
      canvas.width = image.width;
      canvas.height = image.height;
      const context = canvas.getContext('2d');
      context.drawImage(image, 0, 0);
      return regions.map((r) => {
        const data = context.getImageData(Math.round(r.x), Math.round(r.y), Math.max(1, Math.round(r.w)),
                                          Math.max(1, Math.round(r.h))).data;
        let coloured = 0;
        for (let i = 0; i < data.length; i += 4) {
          const r = data[i], g = data[i + 1], b = data[i + 2];
          if (Math.max(r, g, b) - Math.min(r, g, b) > 60) ++coloured;
        }
        return coloured;
      });
    }, { png: shot.toString('base64'), regions: charts });
    charts.forEach((c, i) => {
      console.log(`chart ${i} (${c.cls}) ${Math.round(c.w)}x${Math.round(c.h)}: ${counts[i]} coloured pixels`);
      if (counts[i] < 100) failures.push(`chart ${i} (${c.cls}) is blank`);
    });
    if (external.length) failures.push('the page requested ' + external.join(', '));
  });
  if (failures.length) {
    console.log('FAIL: ' + failures.join('; '));
    process.exit(1);
  }
  console.log('PASS');
}

main().catch((e) => {
  console.log('FAIL: ' + (e && e.stack ? e.stack : e));
  process.exit(1);
});
