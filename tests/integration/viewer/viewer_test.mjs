// Opens mocapd's viewer page in Debian's headless chromium (playwright-core drives it; it
// never downloads a browser), waits for frames, takes two screenshots 700 ms apart and
// checks that the skeleton is drawn (saturated, non-grey pixels outside the panel) and
// that it moves (pixels that differ between the shots).
// Before the shots it presses "Calibrate (T-pose)" and answers the token prompt (the
// simulated subject stands in a T-pose for its first seconds), and waits for calibrated
// frames. Usage: node viewer_test.mjs URL TOKEN OUT_DIR [SAVE_PNG]
import { openBrowser } from './chromium.mjs';
import { writeFileSync } from 'node:fs';
import { join } from 'node:path';

const [url, token, outDir, savePng] = process.argv.slice(2);
if (!url || !token || !outDir) {
  console.error('usage: node viewer_test.mjs URL TOKEN OUT_DIR [SAVE_PNG]');
  process.exit(2);
}
const fail = (msg) => { console.error(`FAIL: ${msg}`); process.exitCode = 1; };

const browser = await openBrowser(720);
const { context } = browser;
try {
  const page = context.pages()[0] ?? await context.newPage();
  const errors = [];
  page.on('pageerror', (e) => errors.push(String(e)));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  page.on('dialog', (d) => d.accept(token));  // the control token prompt
  await page.goto(url, { waitUntil: 'load' });
  await page.waitForFunction(() => window.mocapViewer && window.mocapViewer.frames > 20, null, { timeout: 30000 });
  await page.click('#calibrate-t');
  await page.waitForFunction(() => window.mocapViewer.calibrated, null, { timeout: 15000 });
  const message = await page.textContent('#message');
  if (!message.includes('done')) fail(`calibrate button: ${message}`);
  await page.waitForTimeout(2500);  // into the walk
  await page.waitForTimeout(1200);  // the panel's rate/latency refresh every 500 ms
  const state = await page.evaluate(() => ({ ...window.mocapViewer, hello: undefined }));
  console.log('scene:', JSON.stringify(await page.evaluate(() => window.mocapViewer.scene())));
  console.log(`viewer: ${state.frames} frames, ${state.fps} Hz, latency ${state.latencyMs} ms (wall clock), subject ${state.subject}`);
  // Software WebGL on a loaded CI machine renders slowly; the stream keeps going (the
  // server drops what the page cannot take), so only require a live stream.
  if (state.fps < 10) fail(`frame rate ${state.fps} Hz in the browser`);
  if (!Number.isFinite(state.latencyMs)) fail('no latency shown');
  // Body-aware fusion ([fusion] heading = "auto", the default): once calibrated, the knees'
  // constraints hold the calves' headings, and the page says so for each segment.
  await page.waitForFunction(() => {
    const h = window.mocapViewer.headings();
    const names = window.mocapViewer.hello.segments.map((s) => s.name);
    return h[names.indexOf('left_calf')] === 'joints' && h[names.indexOf('right_calf')] === 'joints';
  }, null, { timeout: 30000 });
  const headings = await page.evaluate(() => window.mocapViewer.headings());
  console.log('headings:', JSON.stringify(headings));
  if (!headings.includes('mag') && !headings.includes('gyro')) fail('the root shows no absolute heading source');

  const panel = await page.locator('#panel').boundingBox();
  const shotA = await page.screenshot();
  await page.waitForTimeout(700);
  const shotB = await page.screenshot();
  writeFileSync(join(outDir, 'viewer-a.png'), shotA);
  writeFileSync(join(outDir, 'viewer-b.png'), shotB);
  if (savePng) writeFileSync(savePng, shotB);

  // Decode both PNGs in the page itself (no PNG library needed) and compare.
  const stats = await page.evaluate(async ({ a, b, panel }) => {
    const decode = async (b64) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const c = document.createElement('canvas');
      c.width = img.width;
      c.height = img.height;
      const ctx = c.getContext('2d');
      ctx.drawImage(img, 0, 0);
      return ctx.getImageData(0, 0, c.width, c.height);
    };
    const [A, B] = [await decode(a), await decode(b)];
    const inPanel = (x, y) => x >= panel.x - 2 && x <= panel.x + panel.width + 2 &&
                              y >= panel.y - 2 && y <= panel.y + panel.height + 2;
    // Skeleton pixels: saturated colour (bones) or near-white (joints); the background
    // (#1b1e24) and the grid are grey.
    const skeleton = (d, i) => {
      const r = d[i], g = d[i + 1], bl = d[i + 2];
      return Math.max(r, g, bl) - Math.min(r, g, bl) > 60 || Math.min(r, g, bl) > 200;
    };
    let drawnA = 0, drawnB = 0, moved = 0;
    for (let y = 0; y < A.height; ++y) {
      for (let x = 0; x < A.width; ++x) {
        if (inPanel(x, y)) continue;
        const i = 4 * (y * A.width + x);
        const sa = skeleton(A.data, i), sb = skeleton(B.data, i);
        drawnA += sa;
        drawnB += sb;
        if (sa !== sb) moved += 1;
      }
    }
    return { drawnA, drawnB, moved };
  }, { a: shotA.toString('base64'), b: shotB.toString('base64'), panel });
  console.log(`skeleton pixels: ${stats.drawnA} and ${stats.drawnB}; changed between shots: ${stats.moved}`);
  if (stats.drawnA < 800 || stats.drawnB < 800) fail('the skeleton is not drawn');
  if (stats.moved < 200) fail('the skeleton does not move between the screenshots');
  if (errors.length) fail(`page errors: ${errors.join('; ')}`);
} finally {
  await browser.close();
}
