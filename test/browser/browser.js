// The one way the web-page tests start a browser: Debian's chromium, headless, driven by
// playwright-core (scripts/install_deps.sh installs both). Used as
//   const { withPage } = require('./browser');
//   await withPage(async (page) => { await page.goto(url); ... });
// Blocks every request that leaves localhost / file://, and records it, so that a test can assert
// that a page needs no network.
'use strict';
const fs = require('fs');
const { chromium } = require('playwright-core');

const CANDIDATES = [process.env.ACT_CHROMIUM, '/usr/bin/chromium', '/usr/bin/chromium-browser'];

function chromiumPath() {
  const found = CANDIDATES.find((p) => p && fs.existsSync(p));
  if (!found) {
    throw new Error('chromium not found (tried ' + CANDIDATES.filter(Boolean).join(', ') +
                    '): run scripts/install_deps.sh');
  }
  return found;
}

function isLocal(url) {
  return /^(file:|data:|blob:|about:)/.test(url) ||
         /^https?:\/\/(127\.0\.0\.1|localhost|\[::1\])(:\d+)?\//.test(url);
}

// Runs fn(page, external) with a fresh page; external lists the blocked non-local URLs requested.
async function withPage(fn, { width = 1280, height = 900 } = {}) {
  const browser = await chromium.launch({
    executablePath: chromiumPath(),
    headless: true,
    args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage'],
  });
  try {
    const context = await browser.newContext({ viewport: { width, height } });
    const external = [];
    await context.route('**/*', (route) => {
      const url = route.request().url();
      if (isLocal(url)) return route.continue();
      external.push(url);
      return route.abort();
    });
    const page = await context.newPage();
    return await fn(page, external);
  } finally {
    await browser.close();
  }
}

module.exports = { withPage, chromiumPath };
