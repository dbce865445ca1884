// Opens a `pipeline report` page in the system's Chromium (headless, driven by
// puppeteer-core; no browser is downloaded) from the file system, as a user's double-click
// would, and checks it: no console error, no failed load, the 3D view has drawn the model
// where its vertices project, moving the slider to frame 4 changes the overlay and the
// model's pose. Saves screenshots. Usage:
//   node tools/check_report.cjs OUTPUT/report/index.html SCREENSHOT_DIR
// Prints one JSON line of figures; exits 1 with the reasons on failure.
'use strict';
const path = require('path');
const puppeteer = require('puppeteer-core');

(async () => {
  const [page_file, shots] = process.argv.slice(2);
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    // WebGL without a GPU: Chromium's software renderer.
    args: ['--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader'],
  });
  const problems = [];
  try {
    const page = await browser.newPage();
    page.on('console', (m) => { if (m.type() === 'error') problems.push('console error: ' + m.text()); });
    page.on('pageerror', (e) => problems.push('page error: ' + e));
    page.on('requestfailed', (r) => problems.push('failed to load ' + r.url()));
    await page.setViewport({ width: 1280, height: 900 });
    const started = Date.now();
    await page.goto('file://' + path.resolve(page_file), { waitUntil: 'load' });
    await page.waitForFunction(() => document.body.dataset.ready === 'yes', { timeout: 20000 });
    const loadSeconds = (Date.now() - started) / 1000;
    const state = () => page.evaluate(() => {
      const r = window.hullposeReport;
      const points = r.modelScreenPoints(5);
      const img = document.getElementById('overlay');
      return { frame: r.frames[r.current()], src: r.overlaySrc(), points, drawn: r.drawnShare(points),
        overlayLoaded: img.complete && img.naturalWidth > 0 };
    });
    const overlayLoaded = () => page.waitForFunction(() => {
      const i = document.getElementById('overlay');
      return i.complete && i.naturalWidth > 0;
    });
    await page.evaluate(() => window.hullposeReport.setFrame(0));
    await overlayLoaded();
    const first = await state();
    await page.screenshot({ path: path.join(shots, 'report-frame0.png') });
    // The slider, as a user moves it.
    await page.$eval('#slider', (s) => { s.value = '4'; s.dispatchEvent(new Event('input')); });
    await overlayLoaded();
    const fourth = await state();
    await page.screenshot({ path: path.join(shots, 'report-frame4.png') });
    await page.$eval('#show-graphcut', (c) => { c.checked = true; c.dispatchEvent(new Event('change')); });
    await page.screenshot({ path: path.join(shots, 'report-frame4-surface.png'), fullPage: true });
    let moved = 0;
    first.points.forEach((p, i) => { moved += Math.hypot(p[0] - fourth.points[i][0], p[1] - fourth.points[i][1]); });
    moved /= Math.max(1, first.points.length);
    if (!(first.drawn > 0.8)) problems.push('frame 0: the model drawn at ' + first.drawn.toFixed(3) + ' of its projected vertices');
    if (!(fourth.drawn > 0.8)) problems.push('frame 4: the model drawn at ' + fourth.drawn.toFixed(3) + ' of its projected vertices');
    if (fourth.frame !== 4) problems.push('the slider moved to frame ' + fourth.frame + ', not 4');
    if (!/000004\.png$/.test(fourth.src || '') || fourth.src === first.src) problems.push('the overlay did not change to frame 4: ' + fourth.src);
    if (!first.overlayLoaded || !fourth.overlayLoaded) problems.push('an overlay picture did not load');
    if (!(moved > 2)) problems.push('the model did not move between frames 0 and 4 (' + moved.toFixed(2) + ' px)');
    console.log(JSON.stringify({ loadSeconds, drawn: [first.drawn, fourth.drawn], movedPx: moved, overlay: [first.src, fourth.src] }));
  } finally {
    await browser.close();
  }
  if (problems.length) {
    console.error(problems.join('\n'));
    process.exit(1);
  }
})().catch((e) => { console.error(String(e && e.stack || e)); process.exit(1); });
