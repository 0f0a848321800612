// The viewer's Takes panel in Debian's headless chromium (playwright-core, no downloaded
// browser): a wrong token is refused and records nothing; a take started and stopped from
// the panel with the token is listed; loading it plays it into the 3D view (frame index
// and time advance, the live stream is not drawn), pause stops the clock, the scrubber
// moves it to a chosen time and the drawn pose changes (with the live bone lengths and
// height: units and axes); at the end the live view resumes.
// Usage: node takes_test.mjs URL TOKEN
import { openBrowser } from './chromium.mjs';

const [url, token] = process.argv.slice(2);
if (!url || !token) {
  console.error('usage: node takes_test.mjs URL TOKEN');
  process.exit(2);
}
const fail = (msg) => { throw new Error(msg); };
const kWait = { timeout: 60000 };

const browser = await openBrowser(900);
const { context } = browser;
try {
  const page = context.pages()[0] ?? await context.newPage();
  const errors = [];
  page.on('pageerror', (e) => errors.push(String(e)));
  page.on('console', (m) => {
    // The refused start answers 401, which chromium logs as a failed resource.
    if (m.type() === 'error' && !m.text().includes('401')) errors.push(m.text());
  });
  await page.goto(url, { waitUntil: 'load' });
  await page.waitForFunction(() => window.mocapViewer && window.mocapViewer.frames > 20 && window.mocapTakes, null, kWait);
  await page.click('#takes summary');

  // A wrong token: refused, nothing recorded.
  await page.fill('#takes-token', 'not-the-token');
  await page.fill('#takes-name', 'refused1');
  await page.click('#takes-start');
  await page.waitForFunction(() => document.getElementById('takes-message').textContent.startsWith('refused'), null, kWait);
  console.log(`wrong token: ${await page.textContent('#takes-message')}`);
  if (await page.locator('#takes-list li[data-take="refused1"]').count()) fail('a refused take is listed');

  // Into the walk (the simulated subject stands for its first 6 s, which began before the
  // page's first frame), then record about three seconds of samples from the panel. Sample
  // time, not frames counted: a slow software-rendered page is sent fewer frames.
  const firstUs = await page.evaluate(() => window.mocapViewer.sampleUs);
  const sampleAfter = (us) => page.waitForFunction((t) => window.mocapViewer.sampleUs > t, us, kWait);
  await sampleAfter(firstUs + 7e6);
  const livePose = await page.evaluate(() => window.mocapViewer.pose());
  const parents = await page.evaluate(() => window.mocapViewer.hello.segments.map((s) => s.parent));
  await page.fill('#takes-token', token);
  await page.fill('#takes-name', 'panel1');
  await page.fill('#takes-notes', 'from the viewer test');
  await page.click('#takes-start');
  await page.waitForSelector('#takes-list li[data-take="panel1"]', kWait);
  await sampleAfter(await page.evaluate(() => window.mocapViewer.sampleUs) + 3e6);
  await page.click('#takes-stop');
  await page.waitForFunction(() => document.getElementById('takes-message').textContent === 'take panel1: stopped', null, kWait);
  await page.waitForSelector('#takes-list li[data-take="panel1"] button', kWait);
  console.log(`listed: ${await page.textContent('#takes-list li[data-take="panel1"]')}`);

  // Playback: the clock and the frame index advance, the live stream is not drawn.
  await page.click('#takes-list li[data-take="panel1"] button');
  await page.waitForFunction(() => window.mocapTakes.playing && window.mocapTakes.frame > 10, null, kWait);
  const playing = await page.evaluate(() => ({ ...window.mocapTakes, live: window.mocapViewer.live }));
  console.log(`playing: ${JSON.stringify(playing)}`);
  if (playing.live) fail('the live stream is drawn during playback');
  if (playing.duration < 2) fail(`take of ${playing.duration} s`);
  await page.waitForFunction((f) => window.mocapTakes.frame > f + 10, playing.frame, kWait);

  // Pause stops the clock: the time stays put across several rendered frames.
  await page.click('#takes-play');
  const paused = await page.evaluate(() => window.mocapTakes.time);
  await page.evaluate(() => new Promise((done) => {
    let n = 0;
    const count = () => (++n >= 30 ? done() : requestAnimationFrame(count));
    requestAnimationFrame(count);
  }));
  const after = await page.evaluate(() => window.mocapTakes);
  if (after.playing || after.time !== paused) fail(`pause: time ${paused} -> ${after.time}`);

  // The scrubber: to 0.5 s, then to 2.0 s; the drawn pose follows.
  const scrub = async (t) => {
    await page.locator('#takes-scrub').evaluate((el, v) => {
      el.value = String(v);
      el.dispatchEvent(new Event('input', { bubbles: true }));
    }, t);
    return page.evaluate(() => ({ time: window.mocapTakes.time, frame: window.mocapTakes.frame, pose: window.mocapViewer.pose() }));
  };
  const a = await scrub(0.5);
  const b = await scrub(2.0);
  console.log(`scrub: ${a.time.toFixed(2)} s frame ${a.frame} -> ${b.time.toFixed(2)} s frame ${b.frame}`);
  if (Math.abs(a.time - 0.5) > 0.02 || Math.abs(b.time - 2.0) > 0.02) fail('the scrubber did not move the time');
  if (a.pose.length < 10) fail(`${a.pose.length} segments drawn`);
  let moved = 0;
  a.pose.forEach((p, i) => { moved = Math.max(moved, Math.hypot(p[0] - b.pose[i][0], p[1] - b.pose[i][1], p[2] - b.pose[i][2])); });
  console.log(`largest segment move between 0.5 s and 2.0 s: ${moved.toFixed(3)} m`);
  if (moved < 0.05) fail('the drawn pose does not change with the scrubber');
  // Same body, same frame: the played pose has the live pose's bone lengths (units) and
  // height span (axes: z up), and its root stands about a metre up.
  const dist = (p, q) => Math.hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]);
  const span = (pose) => Math.max(...pose.map((p) => p[2])) - Math.min(...pose.map((p) => p[2]));
  parents.forEach((parent, i) => {
    if (parent < 0) return;
    const l = dist(livePose[i], livePose[parent]), r = dist(b.pose[i], b.pose[parent]);
    if (Math.abs(l - r) > 0.01) fail(`segment ${i}: ${r.toFixed(3)} m from its parent when played, ${l.toFixed(3)} m live`);
  });
  console.log(`height span live ${span(livePose).toFixed(3)} m, played ${span(b.pose).toFixed(3)} m; root at ${b.pose[0][2].toFixed(3)} m`);
  if (Math.abs(span(livePose) - span(b.pose)) > 0.1) fail('the played skeleton does not stand like the live one');
  if (b.pose[0][2] < 0.5 || b.pose[0][2] > 1.5) fail(`root at ${b.pose[0][2]} m: wrong axes or units`);

  // Play to the end: the live stream resumes.
  await page.click('#takes-play');
  await page.waitForFunction(() => !window.mocapTakes.playing && window.mocapViewer.live, null, kWait);
  if (errors.length) fail(`page errors: ${errors.join('; ')}`);
  console.log('takes panel: ok');
} catch (err) {
  console.error(`FAIL: ${err.message}`);
  process.exitCode = 1;
} finally {
  await browser.close();
}
