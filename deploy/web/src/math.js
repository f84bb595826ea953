// Quaternions (w, x, y, z), Hamilton product, and forward kinematics: the formulas of deploy/README.md
// ("The model contract") in plain JavaScript numbers (float64), as refimpl's NumPy does them.
// Shapes: a pose's quaternions are an Array of J [w, x, y, z]; a clip is {rot: F x J x 4, pos: F x 3}.

export function qmul(a, b) {
  return [
    a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
    a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
    a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
    a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
  ];
}

export const qconj = (q) => [q[0], -q[1], -q[2], -q[3]];

export function qnormalize(q) {
  const n = Math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  return [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
}

export const qdot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];

// rotate(q, v): the vector part of q (0, v) conj(q) = v + 2 (w (u x v) + u x (u x v)), u = (x, y, z).
export function qrotate(q, v) {
  const [w, x, y, z] = q;
  const a = [y * v[2] - z * v[1], z * v[0] - x * v[2], x * v[1] - y * v[0]];
  const b = [y * a[2] - z * a[1], z * a[0] - x * a[2], x * a[1] - y * a[0]];
  return [v[0] + 2 * (w * a[0] + b[0]), v[1] + 2 * (w * a[1] + b[1]), v[2] + 2 * (w * a[2] + b[2])];
}

// The twist about +y of a root rotation: normalise(w, 0, y, 0), the identity when w = y = 0.
export function heading(q) {
  const n = Math.sqrt(q[0] * q[0] + q[2] * q[2]);
  return n > 1e-9 ? [q[0] / n, 0, q[2] / n, 0] : [1, 0, 0, 0];
}

const AXIS = { x: 1, y: 2, z: 3 };

// q_order[0](a0) q_order[1](a1) q_order[2](a2), angles in radians (refimpl.rotations.quat_from_euler).
export function quatFromEuler(angles, order) {
  let q = [1, 0, 0, 0];
  for (let i = 0; i < 3; i++) {
    const e = [Math.cos(angles[i] / 2), 0, 0, 0];
    e[AXIS[order[i]]] = Math.sin(angles[i] / 2);
    q = i === 0 ? e : qmul(q, e);
  }
  return q;
}

// Angles (z, y, x) in degrees with q = q_z(a) q_y(b) q_x(c): a BVH "Zrotation Yrotation Xrotation" channel triple.
export function eulerZYXDegrees(q) {
  const [w, x, y, z] = qnormalize(q);
  const r20 = 2 * (x * z - w * y), r21 = 2 * (y * z + w * x), r22 = 1 - 2 * (x * x + y * y);
  const r10 = 2 * (x * y + w * z), r00 = 1 - 2 * (y * y + z * z);
  const d = 180 / Math.PI;
  return [Math.atan2(r10, r00) * d, Math.asin(Math.max(-1, Math.min(1, -r20))) * d, Math.atan2(r21, r22) * d];
}

// Antipodal continuity over time (refimpl.quat.quat_fix): frame t negated when an odd number of the input's
// consecutive dot products up to t are negative. rot: F x J x 4 -> a new array.
export function quatFix(rot) {
  const F = rot.length, J = F ? rot[0].length : 0;
  const out = rot.map((f) => f.map((q) => q.slice()));
  for (let j = 0; j < J; j++) {
    let flips = 0;
    for (let t = 1; t < F; t++) {
      if (qdot(rot[t][j], rot[t - 1][j]) < 0) flips++;
      if (flips % 2) out[t][j] = out[t][j].map((v) => -v);
    }
  }
  return out;
}

// World joint positions (J x 3) of one pose: pos[j] = pos[parent] + rotate(world[parent], offset[j]).
export function forwardKinematics(parents, offsets, rot, root) {
  const J = parents.length, world = new Array(J), pos = new Array(J);
  for (let j = 0; j < J; j++) {
    const p = parents[j];
    if (p < 0) {
      world[j] = rot[j];
      pos[j] = root.slice();
    } else {
      const o = qrotate(world[p], offsets[j]);
      pos[j] = [pos[p][0] + o[0], pos[p][1] + o[1], pos[p][2] + o[2]];
      world[j] = qmul(world[p], rot[j]);
    }
  }
  return pos;
}
