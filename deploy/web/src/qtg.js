// QTG in the page: a BVH clip to the model's 22-joint rig at its frame rate (refimpl.protocols.transition.
// load_source), the four context poses into the window frame (make_windows, the metadata's input_transform),
// the rollout graph, and back to the world (window_to_world, output_transform); two clips are joined as
// refimpl generate does (refimpl.tasks.transition_generate.make_transition, _align_target).
// Shapes: a clip {rot: F x J x 4, pos: F x 3 (cm)}; a pose vector P = 3 + 4 J.
import { heading, qconj, qmul, qnormalize, qrotate, quatFix } from "./math.js";

// Centimetres per file length unit of the rigs `python -m deploy run --joints` names (refimpl.rigs.RIGS).
export const RIG_UNIT_CM = { cmu: 2.54 / 0.45, salsa: 1.0 };

// 1 / frame_time snapped to the nearest integer within 0.1 % (refimpl.protocols.transition.declared_rate).
export function declaredRate(frameTime) {
  const fps = 1 / frameTime;
  return Math.abs(fps - Math.round(fps)) <= 1e-3 * fps ? Math.round(fps) : fps;
}

// The joints named in `keep` (skeleton order, root first) of a parsed BVH, the others removed with their
// rotation pushed into their children and offsets composed (refimpl.skeleton.remove_joints, "compose").
export function subsetJoints(bvh, keep, where) {
  const idx = keep.map((n) => bvh.names.indexOf(n));
  const missing = keep.filter((_, i) => idx[i] < 0);
  if (missing.length) throw new Error(`${where}: a clip of another rig (no joint ${missing.slice(0, 3).join(", ")}${missing.length > 3 ? ", ..." : ""} of the model's skeleton)`);
  if (idx[0] !== 0 || idx.some((v, i) => i && v <= idx[i - 1])) throw new Error(`${where}: the model's joints are not in this clip's hierarchy order (another rig)`);
  const J = bvh.names.length, kept = new Set(idx);
  const parents = bvh.parents.slice(), offs = bvh.offsets.map((o) => o.slice());
  const rot = bvh.rot.map((f) => f.map((q) => q.slice()));
  for (let r = 0; r < J; r++) {
    if (kept.has(r)) continue;
    for (let c = 0; c < J; c++) {
      if (bvh.parents[c] !== r) continue;
      for (const f of rot) f[c] = qmul(f[r], f[c]);
      offs[c] = [offs[r][0] + offs[c][0], offs[r][1] + offs[c][1], offs[r][2] + offs[c][2]];
      parents[c] = parents[r];
    }
    for (const f of rot) f[r] = [1, 0, 0, 0];
  }
  const newIndex = new Map(idx.map((j, i) => [j, i]));
  return {
    skeleton: { names: keep.slice(), parents: idx.map((j, i) => (i ? newIndex.get(parents[j]) : -1)), offsets: idx.map((j) => offs[j]) },
    rot: rot.map((f) => idx.map((j) => f[j])),
  };
}

// A parsed BVH on the model's skeleton at `fps` (phase 0 of the subsampling), lengths in centimetres.
export function clipForModel(bvh, skeletonMeta, unitCm, fps, where) {
  const rate = declaredRate(bvh.frameTime);
  const k = Math.round(rate / fps);
  if (k < 1 || Math.abs(rate / fps - k) > 1e-9) throw new Error(`${where}: its rate ${rate} fps is not an integer multiple of the model's ${fps} fps`);
  const sub = subsetJoints(bvh, skeletonMeta.names, where);
  const skeleton = { ...sub.skeleton, offsets: sub.skeleton.offsets.map((o) => o.map((v) => v * unitCm)) };
  const rot = [], pos = [];
  for (let f = 0; f < sub.rot.length; f += k) { rot.push(sub.rot[f]); pos.push(bvh.pos[f].map((v) => v * unitCm)); }
  return { skeleton, rot, pos, fps };
}

// Four world frames -> [p'_-1, p'_0, g'1, g'2] as flat poses relative to the first (make_windows(length=4)).
export function windowPoses(rot4, pos4) {
  const hinv = qconj(heading(rot4[0][0]));
  let rot = rot4.map((f, k) => f.map((q, j) => (j === 0 ? qmul(hinv, q) : q.slice())));
  rot[0] = rot[0].map((q) => (q[0] < 0 ? q.map((v) => -v) : q));
  rot = quatFix(rot);
  return rot.map((f, k) => {
    const d = [0, 1, 2].map((i) => pos4[k][i] - pos4[0][i]);
    return [...qrotate(hinv, d), ...f.flat()];
  });
}

// Poses (T x P) in the window frame -> world {rot: T x J x 4 (unit), pos: T x 3} (window_to_world).
export function windowToWorld(poses, h, origin) {
  const rot = [], pos = [];
  for (const p of poses) {
    const r = qrotate(h, [p[0], p[1], p[2]]);
    pos.push([r[0] + origin[0], r[1] + origin[1], r[2] + origin[2]]);
    const f = [];
    for (let j = 0; 3 + 4 * j < p.length; j++) {
      const q = [p[3 + 4 * j], p[4 + 4 * j], p[5 + 4 * j], p[6 + 4 * j]];
      f.push(qnormalize(j === 0 ? qmul(h, q) : q));
    }
    rot.push(f);
  }
  return { rot, pos };
}

// The target clip turned and moved to continue the source (transition_generate._align_target).
export function alignTarget(src, s, tgt, g, T) {
  const turn = qmul(heading(src.rot[s][0]), qconj(heading(tgt.rot[g][0])));
  const rot = tgt.rot.map((f) => f.map((q, j) => (j === 0 ? qmul(turn, q) : q.slice())));
  const rel = tgt.pos.map((p) => qrotate(turn, [p[0] - tgt.pos[g][0], p[1] - tgt.pos[g][1], p[2] - tgt.pos[g][2]]));
  const vs = [0, 1, 2].map((i) => src.pos[s][i] - src.pos[s - 1][i]);
  const vt = [0, 1, 2].map((i) => rel[g + 1][i] - rel[g][i]);
  const anchor = [0, 1, 2].map((i) => src.pos[s][i] + (T + 1) * 0.5 * (vs[i] + vt[i]));
  anchor[1] = tgt.pos[g][1];
  return { ...tgt, rot, pos: rel.map((p) => [p[0] + anchor[0], p[1] + anchor[1], p[2] + anchor[2]]) };
}

// The transition from source frame s (the last kept) to target frame g (the first kept): `rollout(past, target)`
// is the exported graph ((1, 2, P) float32 each -> (T, P)). Returns the joined clip {rot, pos, start, stop,
// generated: {rot, pos}, window: {past, target}} with frames [start, stop) generated.
export async function transition(rollout, T, src, s, tgt, g, { align = "auto", sameClip = false, context = 10 } = {}) {
  if (!(Number.isInteger(s) && s >= 1 && s < src.rot.length)) throw new Error(`source frame: expected 1 ... ${src.rot.length - 1}, got ${s}`);
  if (!(Number.isInteger(g) && g >= 0 && g < tgt.rot.length - 1)) throw new Error(`target frame: expected 0 ... ${tgt.rot.length - 2}, got ${g}`);
  const target = align === "continue" || (align === "auto" && !sameClip) ? alignTarget(src, s, tgt, g, T) : tgt;
  const win = windowPoses([src.rot[s - 1], src.rot[s], target.rot[g], target.rot[g + 1]],
                          [src.pos[s - 1], src.pos[s], target.pos[g], target.pos[g + 1]]);
  const poses = await rollout(win.slice(0, 2), win.slice(2));
  const gen = windowToWorld(poses, heading(src.rot[s - 1][0]), src.pos[s - 1]);
  const a = Math.max(0, s - context + 1), b = Math.min(target.rot.length, g + context);
  return {
    rot: [...src.rot.slice(a, s + 1), ...gen.rot, ...target.rot.slice(g, b)],
    pos: [...src.pos.slice(a, s + 1), ...gen.pos, ...target.pos.slice(g, b)],
    start: s + 1 - a, stop: s + 1 - a + T, generated: gen, window: { past: win.slice(0, 2), target: win.slice(2) },
  };
}
