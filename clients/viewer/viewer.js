// viewer.js — draws the poses of one subject streamed by mocapd's WebSocket (/ws?subject=N,
// protocol in server/serve/http_server.hpp) with three.js: a bone per segment from its
// origin to its tip (tip = origin + q * end_m), joints as spheres, links from a parent's
// origin to its children's, a floor grid, orbit controls. Bone colours show each segment's
// stale flags; the sphere at a segment's origin shows where its heading comes from (its
// magnetometer, the body's joints, or the gyroscope alone: docs/fusion.md). Latency is Date.now() minus the sink's send stamp: both wall clocks.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { initTakesPanel } from './takes_panel.js';

const kStale = 1;
const kNeverSeen = 2;
const kCalibrated = 4;
const kHeadingMag = 16;
const kHeadingJoints = 32;
const kHeadingGyro = 64;
const colours = { live: 0x4fc3f7, stale: 0xffa726, never: 0xef5350, link: 0x9e9e9e, joint: 0xeeeeee,
                  mag: 0x7986cb, joints: 0x81c784, gyro: 0xffd54f };

// Where a segment's heading came from, by its flags.
function headingSource(flags) {
  if (flags & kHeadingJoints) return 'joints';
  if (flags & kHeadingMag) return 'mag';
  if (flags & kHeadingGyro) return 'gyro';
  return 'none';
}

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
let subject = Number(params.get('subject') || 0);

// Scene: three.js is y-up; mocapd's world is z-up (ENU), so the skeleton lives in a group
// turned -90° about x: (x, y, z)_world -> (x, z, -y)_three.
const renderer = new THREE.WebGLRenderer({ antialias: true });
renderer.setPixelRatio(window.devicePixelRatio);
$('view').appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x1b1e24);
scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 2.0));
const sun = new THREE.DirectionalLight(0xffffff, 1.5);
sun.position.set(3, 5, 2);
scene.add(sun);
const kGridCell_m = 0.5;
const grid = new THREE.GridHelper(20, 20 / kGridCell_m, 0x8a93a6, 0x4a505e);
scene.add(grid);
const world = new THREE.Group();
world.rotation.x = -Math.PI / 2;
scene.add(world);

const camera = new THREE.PerspectiveCamera(45, 1, 0.05, 200);
camera.position.set(2.6, 1.6, 2.6);
const controls = new OrbitControls(camera, renderer.domElement);
controls.target.set(0, 1.0, 0);
controls.enableDamping = true;
controls.update();

function resize() {
  const w = window.innerWidth;
  const h = window.innerHeight;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);
resize();

// Skeleton meshes, rebuilt from each hello.
const boneGeometry = new THREE.CylinderGeometry(0.025, 0.025, 1, 10);
const linkGeometry = new THREE.CylinderGeometry(0.012, 0.012, 1, 6);
const jointGeometry = new THREE.SphereGeometry(0.035, 12, 8);
let segments = [];
let bones = [];
let links = [];
let joints = [];
const up = new THREE.Vector3(0, 1, 0);

function material(colour) {
  return new THREE.MeshStandardMaterial({ color: colour, roughness: 0.6 });
}

function buildSkeleton(description) {
  for (const m of [...bones, ...links, ...joints]) world.remove(m);
  segments = description.map((s) => ({ ...s, end: new THREE.Vector3(...s.end_m) }));
  bones = segments.map(() => new THREE.Mesh(boneGeometry, material(colours.never)));
  links = segments.map(() => new THREE.Mesh(linkGeometry, material(colours.link)));
  joints = segments.map(() => new THREE.Mesh(jointGeometry, material(colours.joint)));
  for (const m of [...bones, ...links, ...joints]) world.add(m);
}

// Places a unit cylinder between a and b.
function stretch(mesh, a, b) {
  const d = new THREE.Vector3().subVectors(b, a);
  const length = d.length();
  mesh.visible = length > 1e-4;
  if (!mesh.visible) return;
  mesh.position.copy(a).addScaledVector(d, 0.5);
  mesh.scale.set(1, length, 1);
  mesh.quaternion.setFromUnitVectors(up, d.divideScalar(length));
}

const origin = [];
const headings = [];
const tip = new THREE.Vector3();
const q = new THREE.Quaternion();
function applyFrame(f) {
  const n = Math.min(segments.length, f.flags.length);
  for (let i = 0; i < n; ++i) {
    origin[i] = new THREE.Vector3(f.pos[3 * i], f.pos[3 * i + 1], f.pos[3 * i + 2]);
  }
  for (let i = 0; i < n; ++i) {
    q.set(f.q[4 * i + 1], f.q[4 * i + 2], f.q[4 * i + 3], f.q[4 * i]);  // three.js: x, y, z, w
    tip.copy(segments[i].end).applyQuaternion(q).add(origin[i]);
    stretch(bones[i], origin[i], tip);
    const flags = f.flags[i];
    bones[i].material.color.setHex(flags & kNeverSeen ? colours.never : flags & kStale ? colours.stale : colours.live);
    const source = headingSource(flags);
    headings[i] = source;
    joints[i].material.color.setHex(source === 'none' ? colours.joint : colours[source]);
    joints[i].position.copy(origin[i]);
    const p = segments[i].parent;
    if (p >= 0 && p < n) stretch(links[i], origin[p], origin[i]);
    else links[i].visible = false;
  }
  if ($('follow').checked && n > 0) {
    // Keep the root in view as the subject walks: move target and camera together.
    const root = new THREE.Vector3(origin[0].x, origin[0].z, -origin[0].y);
    const delta = new THREE.Vector3(root.x - controls.target.x, 0, root.z - controls.target.z);
    controls.target.add(delta);
    camera.position.add(delta);
    // The floor follows in whole cells, so it still reads as fixed under the feet.
    grid.position.set(Math.round(root.x / kGridCell_m) * kGridCell_m, 0, Math.round(root.z / kGridCell_m) * kGridCell_m);
  }
}

// Stream state, also read by the integration test (window.mocapViewer).
const state = { frames: 0, dropped: 0, subject: 0, sampleUs: 0, fps: 0, latencyMs: NaN, connected: false, calibrated: false, hello: null };
window.mocapViewer = state;
// Scene positions in three.js coordinates (y up), for tests and debugging.
state.scene = () => ({ grid: grid.position.toArray(), camera: camera.position.toArray(),
                       target: controls.target.toArray(), root: origin[0] ? origin[0].toArray() : null });
// The segment origins last drawn (world frame), live or from a take.
state.pose = () => origin.map((o) => o.toArray());
// Each segment's heading source as last drawn: 'mag' | 'joints' | 'gyro' | 'none'.
state.headings = () => headings.slice(0, segments.length);
let latest = null;
let arrivals = [];
let latencies = [];
let socket = null;

function connect() {
  const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
  socket = new WebSocket(`${scheme}://${location.host}/ws?subject=${subject}`);
  const me = socket;
  socket.onopen = () => { state.connected = true; $('state').textContent = 'connected'; };
  socket.onclose = () => {
    if (me !== socket) return;  // replaced by a subject change
    state.connected = false;
    $('state').textContent = 'disconnected, retrying…';
    setTimeout(connect, 1000);
  };
  socket.onmessage = (event) => {
    const m = JSON.parse(event.data);
    if (m.type === 'hello') {
      state.hello = m;
      buildSkeleton(m.segments);
      fillSubjects(m.subjects);
    } else if (m.type === 'frame') {
      const now = Date.now();
      latest = m;
      state.frames += 1;
      state.subject = m.subject;
      state.sampleUs = m.sample_us;
      state.calibrated = m.flags.length > 0 && (m.flags[0] & kCalibrated) !== 0;
      arrivals.push(now);
      const sent = m.stamps.sink_send_us || m.stamps.received_us;
      if (sent) latencies.push(now - sent / 1000);
    } else if (m.type === 'drops') {
      state.dropped = m.dropped_total;
    }
  };
}

function fillSubjects(ids) {
  const select = $('subject');
  if (select.options.length > 1) return;
  for (const id of ids) select.add(new Option(`subject ${id}`, String(id)));
  select.value = String(subject);
}

$('subject').addEventListener('change', (e) => {
  subject = Number(e.target.value);
  const old = socket;
  socket = null;
  old.close();
  state.frames = 0;
  connect();
});

// Control: POST with the token in X-Mocap-Token (asked once, kept for this tab).
async function control(path) {
  let token = sessionStorage.getItem('mocapd-token');
  if (!token) token = window.prompt('mocapd control token ([control] token in mocapd.toml)');
  if (!token) return;
  try {
    const r = await fetch(path, { method: 'POST', headers: { 'X-Mocap-Token': token } });
    const body = await r.json();
    if (r.status === 401) sessionStorage.removeItem('mocapd-token');
    else sessionStorage.setItem('mocapd-token', token);
    $('message').textContent = body.ok ? `${path}: done` : `${path}: ${body.error}`;
  } catch (err) {
    $('message').textContent = `${path}: ${err}`;
  }
}
const current = () => state.subject || subject;
$('calibrate-t').onclick = () => control(`/api/calibrate?subject=${current()}&pose=t`);
$('calibrate-n').onclick = () => control(`/api/calibrate?subject=${current()}&pose=n`);
$('record-start').onclick = () => control('/api/record/start');
$('record-stop').onclick = () => control('/api/record/stop');

setInterval(() => {
  const now = Date.now();
  arrivals = arrivals.filter((t) => now - t <= 1000);
  state.fps = arrivals.length;
  const sorted = latencies.sort((a, b) => a - b);
  state.latencyMs = sorted.length ? sorted[Math.floor(sorted.length / 2)] : NaN;
  latencies = [];
  $('fps').textContent = String(state.fps);
  $('latency').textContent = Number.isNaN(state.latencyMs) ? '–' : state.latencyMs.toFixed(1);
  $('frames').textContent = String(state.frames);
  $('dropped').textContent = String(state.dropped);
}, 500);

// The Takes panel draws a take's frames instead of the live stream while it plays.
let live = true;
let drawn = null;
initTakesPanel({
  segmentNames: () => segments.map((s) => s.name),
  subject: current,
  show: (frame) => { if (segments.length) applyFrame(frame); },
  live: (on) => { live = on; drawn = null; state.live = on; },
});
state.live = live;
function animate() {
  requestAnimationFrame(animate);
  if (live && latest && latest !== drawn && segments.length) {
    applyFrame(latest);
    drawn = latest;
  }
  controls.update();
  renderer.render(scene, camera);
}
connect();
animate();
