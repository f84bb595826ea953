// The long-term walker in the page: the pace network's tracks along a path (refimpl.models.pace.predict_with)
// and the walk loop of refimpl.tasks.locomotion_generate.walk_path (deploy/README.md, "Walking a path"), with the
// exported step graph. Lengths in QuaterNet units (1 unit = 5.6444 cm), 30 fps.
// Shapes: J joints, R = 4 J, the step's x (1, R + 8) -> y (1, R + 2); a path N x 2 (x, z).
import { qmul } from "./math.js";
import { pymod, Spline } from "./spline.js";

export const QUATERNET_UNIT_CM = 5.6444;
export const UNITS_PER_METRE = 100 / QUATERNET_UNIT_CM;
export const SPEEDS = { walk: 0.5, jog: 0.85, run: 1.2 };
export const FPS = 30;
const MIN_AMPLITUDE = 0.1, MIN_FREQUENCY = 0.0;

// A drawn path, (x, z) points in metres, as `python -m deploy run` reads a path CSV (read_path_file).
export function pathFromMetres(points) {
  if (points.length < 2) throw new Error(`path: draw at least two points (got ${points.length})`);
  if (!points.every((p) => Math.abs(p[0]) <= 10000 && Math.abs(p[1]) <= 10000)) throw new Error("path: coordinates outside [-10000, 10000] metres");
  const sp = new Spline(points, false);
  if (sp.length > 10000) throw new Error(`path: ${sp.length.toFixed(1)} m long, more than 10000 m`);
  return new Spline(points.map((p) => [p[0] * UNITS_PER_METRE, p[1] * UNITS_PER_METRE]), false);
}

export function parseSpeed(text) {
  if (text in SPEEDS) return SPEEDS[text];
  const v = Number(text);
  if (!(text !== "" && Number.isFinite(v) && v >= 0.01 && v <= 5)) throw new Error(`speed ${JSON.stringify(text)}: expected walk, jog, run or 0.01 ... 5 units per frame`);
  return v;
}

// Python's round(): halves to even.
export function roundHalfEven(x) {
  const f = Math.floor(x), d = x - f;
  return d > 0.5 || (d === 0.5 && f % 2 !== 0) ? f + 1 : f;
}

// The pace tracks: `pace(x)` runs the graph on x (1, N, 2) float32 and returns y (N x 4) numbers.
export async function paceTracks(pace, path, speed, ppu = 5, smoothing = 1) {
  const sp = path.reparameterize(ppu, smoothing);
  const ta = sp.track("turning_angle");
  const x = new Float32Array(2 * ta.length);
  ta.forEach((a, i) => { x[2 * i] = a[0]; x[2 * i + 1] = speed; });
  const y = await pace(x, ta.length);
  const tan = sp.track("tangent");
  const facing = y.map((r, i) => {
    const n = Math.sqrt(r[2] * r[2] + r[3] * r[3]) + 1e-9, c = r[2] / n, s = r[3] / n, t = tan[i];
    return [t[0] * c - t[1] * s, t[1] * c + t[0] * s];
  });
  return sp.withTracks({ amplitude: [y.map((r) => [Math.max(r[0], MIN_AMPLITUDE)]), "linear"],
                         frequency: [y.map((r) => [Math.max(r[1], MIN_FREQUENCY)]), "linear"],
                         direction: [facing, "circular"] });
}

const angle = (v) => Math.atan2(v[1], v[0]);

// The seed clip (P x (R + 8) numbers) turned about +y so that its last facing is `facing` (align_seed).
export function alignSeed(seed, J, facing) {
  const a = angle([seed[seed.length - 1][4 * J + 6], seed[seed.length - 1][4 * J + 7]]) - angle(facing);
  const r = [Math.cos(a / 2), 0, Math.sin(a / 2), 0], c = Math.cos(a), s = Math.sin(a);
  return seed.map((row) => {
    const out = row.slice();
    const q = qmul(r, row.slice(0, 4));
    for (let i = 0; i < 4; i++) out[i] = q[i];
    for (const i of [4 * J + 4, 4 * J + 6]) {
      const x = row[i], z = row[i + 1];
      out[i] = x * c + z * s; out[i + 1] = -x * s + z * c;
    }
    return out;
  });
}

// The walk: `step(x Float32Array, state) -> {y: Float32Array, state}`; yields one frame at a time,
// {rot: J x 4 (unit), root: [x, y, z], control: 6 numbers, distance}. Stops early at the end of an open path.
export async function* walkPath(step, h0, tracks, J, seed, numFrames) {
  const R = 4 * J;
  const rows = alignSeed(seed, J, tracks.interpolate(0, "direction"));
  let y = null, h = h0;
  for (const row of rows) ({ y, state: h } = await step(Float32Array.from(row), h));
  if (y.length !== R + 2) throw new Error(`step: expected outputs of ${R + 2} values for ${J} joints, got ${y.length}`);
  const last = seed[seed.length - 1];
  let phi = Math.atan2(last[R + 3], last[R + 2]), s = 0;
  for (let f = 0; f < numFrames; f++) {
    let tan = tracks.interpolate(s, "tangent");
    const n = Math.sqrt(tan[0] * tan[0] + tan[1] * tan[1]) + 1e-9;
    tan = [tan[0] / n, tan[1] / n];
    const face = tracks.interpolate(s, "direction");
    const amp = tracks.interpolate(s, "amplitude")[0], freq = tracks.interpolate(s, "frequency")[0];
    const c = [amp * Math.cos(phi), amp * Math.sin(phi), amp * tan[0], amp * tan[1], face[0], face[1]];
    const x = new Float32Array(R + 8);
    x.set(y); x.set(c, R + 2);
    ({ y, state: h } = await step(x, h));
    phi = pymod(phi + freq, 2 * Math.PI);
    s += amp;
    const next = s + y[R];
    if (!tracks.closed && next >= tracks.length) return;
    const xz = tracks.interpolate(next);
    const rot = [];
    for (let j = 0; j < J; j++) {
      const q = [y[4 * j], y[4 * j + 1], y[4 * j + 2], y[4 * j + 3]];
      const m = Math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      rot.push(q.map((v) => v / m));
    }
    yield { rot, root: [xz[0], y[R + 1], xz[1]], control: c, distance: next };
  }
}
