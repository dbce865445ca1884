// Opens a `pipeline report` page from the file system, as a user's double-click would, in
// the system's Chromium (or with BROWSER=firefox, Firefox ESR), headless and driven by
// puppeteer-core (no browser is downloaded), and checks it: no console error, no failed
// load, the 3D view has drawn the model where its vertices project, moving the slider to
// frame 4 changes the overlay and the model's pose. A browser without WebGL (Firefox here:
// headless, no GL driver) must say so in the view and keep the slider and pictures
// working. Saves screenshots. Usage:
//   [BROWSER=firefox] node tools/check_report.cjs OUTPUT/report/index.html SCREENSHOT_DIR
// Prints one JSON line of figures; exits 1 with the reasons on failure.
'use strict';
const path = require('path');
const puppeteer = require('puppeteer-core');

(async () => {
  const [page_file, shots] = process.argv.slice(2);
  const firefox = process.env.BROWSER === 'firefox';
  const browser = await puppeteer.launch(firefox ? {
    browser: 'firefox',
    extraPrefsFirefox: { 'webgl.force-enabled': true, 'webgl.disabled': false },
    executablePath: process.env.FIREFOX || '/usr/bin/firefox-esr',
    headless: true,
  } : {
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    // WebGL without a GPU: Chromium's software renderer.
    args: ['--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader'],
  });
  const problems = [];
  try {
    const page = await browser.newPage();
    // Firefox here has no WebGL (headless, no GL driver): THREE says so on the console, and
    // the page must keep everything else working.
    page.on('console', (m) => {
      if (m.type() === 'error' && !(firefox && /WebGL/.test(m.text()))) problems.push('console error: ' + m.text());
    });
    page.on('pageerror', (e) => problems.push('page error: ' + e));
    page.on('requestfailed', (r) => problems.push('failed to load ' + r.url()));
    await page.setViewport({ width: 1280, height: 900 });
    const started = Date.now();
    await page.goto('file://' + path.resolve(page_file), { waitUntil: 'load' });
    await page.waitForFunction(() => document.body.dataset.ready === 'yes', { timeout: 20000 })
      .catch((e) => { throw new Error('the page never got ready (' + e.message + '): ' + problems.join('; ')); });
    const loadSeconds = (Date.now() - started) / 1000;
    const state = () => page.evaluate(() => {
      const r = window.hullposeReport;
      const points = r.modelScreenPoints(5);
      const img = document.getElementById('overlay');
      return { webgl: r.webgl, frame: r.frames[r.current()], src: r.overlaySrc(), points, drawn: r.drawnShare(points),
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
    await page.$eval('#show-tracked', (c) => { c.checked = true; c.dispatchEvent(new Event('change')); });
    await page.screenshot({ path: path.join(shots, 'report-frame4-surface.png'), fullPage: true });
    const shownSurfaces = await page.evaluate(() => window.hullposeReport.shownSurfaces());
    for (const kind of ['graphcut', 'tracked']) {
      if (!shownSurfaces.includes(kind)) problems.push('the ' + kind + ' surface is not shown when ticked: ' + JSON.stringify(shownSurfaces));
    }
    let moved = 0;
    first.points.forEach((p, i) => { moved += Math.hypot(p[0] - fourth.points[i][0], p[1] - fourth.points[i][1]); });
    moved /= Math.max(1, first.points.length);
    const webgl = first.webgl;
    if (!webgl && !firefox) problems.push('no WebGL in Chromium');
    if (!webgl && !(await page.$('#no-webgl'))) problems.push('no WebGL, and the page does not say so');
    if (webgl && !(first.drawn > 0.8)) problems.push('frame 0: the model drawn at ' + first.drawn.toFixed(3) + ' of its projected vertices');
    if (webgl && !(fourth.drawn > 0.8)) problems.push('frame 4: the model drawn at ' + fourth.drawn.toFixed(3) + ' of its projected vertices');
    if (fourth.frame !== 4) problems.push('the slider moved to frame ' + fourth.frame + ', not 4');
    if (!/000004\.png$/.test(fourth.src || '') || fourth.src === first.src) problems.push('the overlay did not change to frame 4: ' + fourth.src);
    if (!first.overlayLoaded || !fourth.overlayLoaded) problems.push('an overlay picture did not load');
    if (webgl && !(moved > 2)) problems.push('the model did not move between frames 0 and 4 (' + moved.toFixed(2) + ' px)');
    console.log(JSON.stringify({ browser: firefox ? 'firefox' : 'chromium', webgl, loadSeconds, drawn: [first.drawn, fourth.drawn], movedPx: moved, overlay: [first.src, fourth.src] }));
  } finally {
    await browser.close();
  }
  if (problems.length) {
    console.error(problems.join('\n'));
    process.exit(1);
  }
})().catch((e) => { console.error(String(e && e.stack || e)); process.exit(1); });
