// Arc-length parameterised 2-D polylines with tracks (refimpl.splines.Spline, spec/locomotion.md §2): the pace
// network's reparameterised path. Points are (x, z) on the floor; distances in the path's units.
// Shapes: points N x 2; a track N x D (D = 1 linear, 2 circular directions).
export const TANGENT_EPS = 1e-9;
export const SLERP_MIN_ANGLE = 1e-3;
const BUILTIN = ["tangent", "turning_angle", "curvature"];

const norm2 = (v) => Math.sqrt(v[0] * v[0] + v[1] * v[1]);

function segments(p, closed) {
  const n = p.length, out = [];
  for (let i = 0; i < (closed ? n : n - 1); i++) {
    const q = p[(i + 1) % n];
    out.push([q[0] - p[i][0], q[1] - p[i][1]]);
  }
  return out;
}

function tangents(p, closed) {
  const seg = segments(p, closed);
  if (!closed) seg.push(seg[seg.length - 1]);
  return seg.map((s) => { const l = norm2(s) + TANGENT_EPS; return [s[0] / l, s[1] / l]; });
}

const signedAngle = (a, b) => Math.atan2(a[0] * b[1] - a[1] * b[0], a[0] * b[0] + a[1] * b[1]);

function turning(p, closed) {
  const n = p.length, segLen = segments(p, closed).map(norm2), tan = tangents(p, closed);
  let ang, ell;
  if (closed) {
    ang = tan.map((t, i) => signedAngle(t, tan[(i + 1) % n]));
    ell = segLen.map((l, i) => 0.5 * (l + segLen[(i + 1) % n]));
  } else {
    if (n < 3) return [new Array(n).fill(0), new Array(n).fill(0)];
    const inner = [], ellIn = [];
    for (let i = 0; i < n - 2; i++) { inner.push(signedAngle(tan[i], tan[i + 1])); ellIn.push(0.5 * (segLen[i] + segLen[i + 1])); }
    ang = [...inner, inner[n - 3], inner[n - 3]];
    ell = [...ellIn, ellIn[n - 3], ellIn[n - 3]];
  }
  return [ang, ang.map((a, i) => a / Math.max(ell[i], TANGENT_EPS))];
}

// scipy.ndimage.gaussian_filter1d (order 0, truncate 4) along the rows of x (N x D): "reflect" or "wrap".
export function gaussianFilter1d(x, sigma, mode) {
  if (sigma === 0 || !x.length) return x.map((r) => r.slice());
  const radius = Math.floor(4 * sigma + 0.5), w = [];
  let sum = 0;
  for (let k = -radius; k <= radius; k++) { const v = Math.exp(-0.5 * (k / sigma) ** 2); w.push(v); sum += v; }
  for (let k = 0; k < w.length; k++) w[k] /= sum;
  const n = x.length, D = x[0].length;
  const at = (j) => {
    if (mode === "wrap") return ((j % n) + n) % n;
    const m = ((j % (2 * n)) + 2 * n) % (2 * n);
    return m >= n ? 2 * n - 1 - m : m;
  };
  return x.map((_, i) => {
    const out = new Array(D).fill(0);
    for (let k = -radius; k <= radius; k++) {
      const r = x[at(i + k)];
      for (let d = 0; d < D; d++) out[d] += w[k + radius] * r[d];
    }
    return out;
  });
}

function slerp2(a, b, t) {
  const na = norm2(a), nb = norm2(b);
  const c = Math.min(1, Math.max(-1, (a[0] * b[0] + a[1] * b[1]) / Math.max(na * nb, 1e-300)));
  const om = Math.acos(c);
  if (om < SLERP_MIN_ANGLE) return [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
  const s = Math.sin(om), u = Math.sin((1 - t) * om), v = Math.sin(t * om);
  return [(u * a[0] + v * b[0]) / s, (u * a[1] + v * b[1]) / s];
}

// Python's float modulo (the result has the sign of m).
export const pymod = (a, m) => { const r = a % m; return r !== 0 && (r < 0) !== (m < 0) ? r + m : r; };

export class Spline {
  constructor(points, closed = false, tracks = {}) {
    if (points.length < (closed ? 3 : 2)) throw new Error(`path: expected at least ${closed ? 3 : 2} points, got ${points.length}`);
    if (!points.every((p) => p.length === 2 && Number.isFinite(p[0]) && Number.isFinite(p[1]))) throw new Error("path: expected finite (x, z) points");
    this.points = points.map((p) => p.slice());
    this.closed = closed;
    this.segLen = segments(this.points, closed).map(norm2);
    const k = this.segLen.findIndex((l) => !(l > 0));
    if (k >= 0) throw new Error(`path: segment ${k} has zero length (points ${k} and ${(k + 1) % points.length} coincide)`);
    this.cum = [0];
    for (const l of this.segLen) this.cum.push(this.cum[this.cum.length - 1] + l);
    this.length = this.cum[this.cum.length - 1];
    const [ang, curv] = turning(this.points, closed);
    this.tracks = { tangent: [tangents(this.points, closed), "circular"], turning_angle: [ang.map((a) => [a]), "linear"], curvature: [curv.map((c) => [c]), "linear"] };
    for (const [name, [v, kind]] of Object.entries(tracks)) this.tracks[name] = [v.map((r) => (Array.isArray(r) ? r.slice() : [r])), kind];
  }

  track(name) { return this.tracks[name][0]; }

  withTracks(tracks) {
    const extra = Object.fromEntries(Object.entries(this.tracks).filter(([n]) => !BUILTIN.includes(n)));
    const sp = new Spline(this.points, this.closed, { ...extra, ...tracks });
    for (const n of BUILTIN) if (!(n in tracks)) sp.tracks[n] = this.tracks[n];
    return sp;
  }

  locate(d) {
    const n = this.points.length;
    if (this.closed) d = pymod(d, this.length);
    let lo = 0, hi = this.cum.length;            // searchsorted(cum, d, "right") - 1
    while (lo < hi) { const mid = (lo + hi) >> 1; if (this.cum[mid] <= d) lo = mid + 1; else hi = mid; }
    const i = Math.min(Math.max(lo - 1, 0), this.closed ? n - 1 : n - 2);
    return [i, this.closed ? (i + 1) % n : i + 1, (d - this.cum[i]) / this.segLen[i]];
  }

  interpolate(d, name = null) {
    const [i, j, t] = this.locate(d);
    const [v, kind] = name === null ? [this.points, "linear"] : this.tracks[name];
    if (kind === "circular") return slerp2(v[i], v[j], t);
    return v[i].map((a, k) => a + t * (v[j][k] - a));
  }

  reparameterize(ppu = 5, smoothing = 1) {
    const L = this.length, d = [];
    if (this.closed) { const n = Math.ceil(L * ppu), step = L / n; for (let i = 0; i < n; i++) d.push(i * step); }
    else { const step = 1 / ppu, n = Math.ceil(L / step); for (let i = 0; i < n; i++) d.push(i * step); }
    if (d.length < (this.closed ? 3 : 2)) throw new Error(`path: too short (${L.toFixed(3)} units gives ${d.length} samples; draw a longer path)`);
    const mode = this.closed ? "wrap" : "reflect", sigma = ppu * smoothing;
    const pts = d.map((x) => this.interpolate(x));
    const smooth = gaussianFilter1d(pts, sigma, mode);
    const [ang, curv] = turning(smooth, this.closed);
    const tracks = { tangent: [tangents(smooth, this.closed), "circular"], turning_angle: [ang.map((a) => [a]), "linear"], curvature: [curv.map((c) => [c]), "linear"] };
    for (const [name, [, kind]] of Object.entries(this.tracks)) {
      if (BUILTIN.includes(name)) continue;
      let vals = d.map((x) => this.interpolate(x, name));
      if (kind === "linear") vals = gaussianFilter1d(vals, sigma, mode);
      tracks[name] = [vals, kind];
    }
    const sp = new Spline(pts, this.closed, {});
    for (const [n, v] of Object.entries(tracks)) sp.tracks[n] = v;
    return sp;
  }
}
