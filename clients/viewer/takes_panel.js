// takes_panel.js — the viewer's Takes panel: lists the takes (GET /api/takes), starts and
// stops a named take (POST /api/takes/start|stop with the control token typed into a
// password field, kept in memory only) and plays a take into the 3D view. Playback
// downloads the take as BVH (GET /api/takes/NAME/download?format=bvh&subject=ID, re-solved
// by mocapd), parses it with three.js's BVHLoader and turns each instant into the frame the
// live view draws (segment origins and world orientations in mocapd's ENU world), so the
// same skeleton is drawn. While a take plays the live stream is not drawn.
import * as THREE from 'three';
import { BVHLoader } from 'three/addons/loaders/BVHLoader.js';

// BVH is Y-up, mocapd's world ENU Z-up: x_enu = Z_bvh, y_enu = X_bvh, z_enu = Y_bvh, i.e.
// q_enu_bvh = (w 0.5, x 0.5, y 0.5, z 0.5) (server/skeleton/bvh.hpp). mocapd writes
// centimetres and lets a position channel replace the root's OFFSET (three's loader adds it).
const kEnuFromBvh = new THREE.Quaternion(0.5, 0.5, 0.5, 0.5);
const kBvhFromEnu = kEnuFromBvh.clone().invert();
const kBvhUnitsPerM = 100;

const $ = (id) => document.getElementById(id);

// view: { segmentNames(): [name], subject(): id, show(frame), live(bool) } from viewer.js.
export function initTakesPanel(view) {
  let token = '';
  let clip = null;  // { name, mixer, bones: [bone|null per segment], root, rootOffset, duration }
  const playback = { take: '', playing: false, time: 0, duration: 0, frame: 0, frameTime: 0, frames: 0 };
  window.mocapTakes = playback;

  const say = (text) => { $('takes-message').textContent = text; };
  // Network failures end up in the panel's message line.
  const guarded = (action) => (...args) => action(...args).catch((err) => say(String(err)));

  async function refresh() {
    // The list comes in pages (at most 500 takes each); `total` says how many there are.
    const takes = [];
    for (;;) {
      const r = await fetch(`/api/takes?offset=${takes.length}`);
      const page = await r.json();
      takes.push(...page.takes);
      if (page.takes.length === 0 || takes.length >= page.total) break;
    }
    const list = $('takes-list');
    list.replaceChildren();
    for (const t of takes) {
      const item = document.createElement('li');
      item.dataset.take = t.name;
      const seconds = t.stop_us ? ((t.stop_us - t.start_us) / 1e6).toFixed(1) + ' s' : t.recording ? 'recording' : 'cut';
      item.textContent = `${t.name} (${seconds}) `;
      if (!t.recording) {
        const play = document.createElement('button');
        play.textContent = 'Load';
        play.onclick = () => guarded(load)(t.name);
        item.append(play);
      }
      list.append(item);
    }
  }

  async function control(path) {
    token = $('takes-token').value || token;
    if (!token) { say('enter the control token'); return; }
    const r = await fetch(path, { method: 'POST', headers: { 'X-Mocap-Token': token } });
    const body = await r.json();
    if (r.status === 401) token = '';
    // A stop that lost samples stopped the take all the same: its reply names it and the loss.
    if (body.ok) say(`take ${body.take}: ${path.includes('/start') ? 'recording' : 'stopped'}`);
    else say(body.take ? `take ${body.take}: ${body.error}` : `refused: ${body.error}`);
    await refresh();
  }

  async function load(name) {
    stop();
    say(`loading ${name}…`);
    const subject = view.subject();
    const r = await fetch(`/api/takes/${name}/download?format=bvh${subject ? `&subject=${subject}` : ''}`);
    if (!r.ok) { say(`${name}: ${r.status} ${await r.text()}`); return; }
    const { skeleton, clip: animation } = new BVHLoader().parse(await r.text());
    const root = skeleton.bones[0];
    const byName = new Map(skeleton.bones.map((b) => [b.name, b]));
    const mixer = new THREE.AnimationMixer(root);
    mixer.clipAction(animation).play();
    const frames = animation.tracks[0].times.length;
    clip = { name, mixer, root, rootOffset: root.position.clone(), bones: view.segmentNames().map((n) => byName.get(n) ?? null) };
    Object.assign(playback, { take: name, time: 0, duration: animation.duration, frames,
                              frameTime: frames > 1 ? animation.duration / (frames - 1) : 0 });
    const scrub = $('takes-scrub');
    scrub.max = String(animation.duration);
    scrub.step = String(playback.frameTime || 0.01);
    $('takes-playing').textContent = name;
    say(`${name}: ${frames} frames`);
    seek(0);
    play();
  }

  // Draws the take at time t (s) through the live view's drawing path.
  function seek(t) {
    if (!clip) return;
    playback.time = Math.min(Math.max(t, 0), playback.duration);
    playback.frame = playback.frameTime ? Math.round(playback.time / playback.frameTime) : 0;
    clip.mixer.setTime(playback.time);
    clip.root.position.sub(clip.rootOffset);
    clip.root.updateMatrixWorld(true);
    const n = clip.bones.length;
    const frame = { pos: new Array(3 * n).fill(0), q: new Array(4 * n).fill(0), flags: new Array(n).fill(0) };
    const p = new THREE.Vector3();
    const q = new THREE.Quaternion();
    clip.bones.forEach((bone, i) => {
      if (!bone) { frame.flags[i] = 2; frame.q[4 * i] = 1; return; }  // not in the BVH: never seen
      bone.getWorldPosition(p);
      bone.getWorldQuaternion(q);
      q.premultiply(kEnuFromBvh).multiply(kBvhFromEnu);
      frame.pos.splice(3 * i, 3, p.z / kBvhUnitsPerM, p.x / kBvhUnitsPerM, p.y / kBvhUnitsPerM);
      frame.q.splice(4 * i, 4, q.w, q.x, q.y, q.z);
    });
    $('takes-scrub').value = String(playback.time);
    $('takes-time').textContent = `${playback.time.toFixed(2)} / ${playback.duration.toFixed(2)} s, frame ${playback.frame}`;
    view.show(frame);
  }

  let last = 0;
  function tick(now) {
    if (!playback.playing) return;
    const t = playback.time + (now - last) / 1000;
    last = now;
    seek(t);
    if (t >= playback.duration) { stop(); return; }
    requestAnimationFrame(tick);
  }
  function play() {
    if (!clip || playback.playing) return;
    if (playback.time >= playback.duration) playback.time = 0;
    playback.playing = true;
    view.live(false);
    $('takes-play').textContent = 'Pause';
    last = performance.now();
    requestAnimationFrame(tick);
  }
  function pause() {
    playback.playing = false;
    $('takes-play').textContent = 'Play';
  }
  // Back to the live stream.
  function stop() {
    pause();
    view.live(true);
  }

  $('takes-start').onclick = () => {
    const q = new URLSearchParams();
    if ($('takes-name').value) q.set('name', $('takes-name').value);
    if ($('takes-notes').value) q.set('notes', $('takes-notes').value);
    return guarded(control)(`/api/takes/start?${q}`);
  };
  $('takes-stop').onclick = () => guarded(control)('/api/takes/stop');
  $('takes-refresh').onclick = guarded(refresh);
  $('takes-play').onclick = () => (playback.playing ? pause() : play());
  $('takes-live').onclick = stop;
  $('takes-scrub').oninput = (e) => { pause(); view.live(false); seek(Number(e.target.value)); };
  guarded(refresh)();
}
