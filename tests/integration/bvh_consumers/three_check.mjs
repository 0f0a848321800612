// three_check.mjs — loads a BVH file with three.js's BVHLoader (a real consumer) and checks
// its joint count and frame count. Node 20, no DOM needed.
//   node three_check.mjs FILE.bvh EXPECTED_JOINTS EXPECTED_FRAMES
// Prints one JSON line; exit 0 when both match, 1 otherwise.
import { readFileSync } from 'node:fs';
import { BVHLoader } from 'three/examples/jsm/loaders/BVHLoader.js';

const [file, joints, frames] = process.argv.slice(2);
const text = readFileSync(file, 'utf8');
const result = new BVHLoader().parse(text);
const bones = result.skeleton.bones.filter((b) => b.name !== 'ENDSITE');
const counts = new Set(result.clip.tracks.map((t) => t.times.length));
const frameCount = Math.max(...counts);
const out = {
  file,
  joints: bones.length,
  frames: frameCount,
  tracks: result.clip.tracks.length,
  duration_s: result.clip.duration,
  root: bones[0]?.name,
};
console.log(JSON.stringify(out));
const ok = bones.length === Number(joints) && frameCount === Number(frames) && counts.size === 1;
process.exit(ok ? 0 : 1);
