// File formats read and written in the page: BVH (read as refimpl.bvh.read_bvh does: Euler channels in their
// written order, degrees, End Sites as joints with the identity rotation, quat_fix over time), exp-map text
// (refimpl.expmap.read_expmap: q = quat_from_axis_angle(-v)), .npy arrays (little-endian float32/float64).
// Errors are thrown as Error with a one-line message naming the file and the line.
import { eulerZYXDegrees, quatFix, quatFromEuler } from "./math.js";

export const MAX_BYTES = 64 * 1024 * 1024;
export const MAX_JOINTS = 1024;
export const MAX_VALUES = 1 << 25;

const CHANNELS = ["xposition", "yposition", "zposition", "xrotation", "yrotation", "zrotation"];

function tokens(text) {
  const out = [];
  const lines = text.split("\n");
  for (let i = 0; i < lines.length; i++) {
    for (const t of lines[i].trim().split(/\s+/)) if (t) out.push([t, i + 1]);
  }
  return out;
}

function number(tok, where, what) {
  const v = Number(tok[0]);
  if (tok[0] === "" || !Number.isFinite(v)) throw new Error(`${where}:${tok[1]}: ${what}: expected a number, got ${JSON.stringify(tok[0].slice(0, 30))}`);
  return v;
}

// {names, parents, offsets (J x 3), channels (J lists), end (J booleans), frameTime, rot (F x J x 4), pos (F x 3)}
export function parseBvh(text, where = "clip.bvh") {
  if (text.length > MAX_BYTES) throw new Error(`${where}: larger than ${MAX_BYTES / 1048576} MB`);
  if (text.indexOf("\u0000") >= 0) throw new Error(`${where}: NUL byte (not a text file)`);
  text = text.replace(/^\uFEFF/, "").replace(/\r\n?/g, "\n");
  const m = /^\s*MOTION\s*$/m.exec(text);
  if (!/^\s*HIERARCHY\b/.test(text)) throw new Error(`${where}:1: not a BVH file (expected HIERARCHY)`);
  if (!m) throw new Error(`${where}: no MOTION section (truncated file?)`);
  const headLines = text.slice(0, m.index).split("\n").length;
  const toks = tokens(text.slice(0, m.index));
  let k = 0;
  const next = (what) => {
    if (k >= toks.length) throw new Error(`${where}:${headLines}: truncated hierarchy (expected ${what})`);
    return toks[k++];
  };
  const names = [], parents = [], offsets = [], channels = [], end = [];
  const stack = [];
  next("HIERARCHY");
  const root = next("ROOT");
  if (root[0].toUpperCase() !== "ROOT") throw new Error(`${where}:${root[1]}: expected ROOT, got ${root[0]}`);
  const open = (parent, isEnd, name, line) => {
    const b = next("'{'");
    if (b[0] !== "{") throw new Error(`${where}:${b[1]}: expected '{' after ${name}`);
    if (names.length >= MAX_JOINTS) throw new Error(`${where}:${line}: more than ${MAX_JOINTS} joints`);
    if (!isEnd && names.includes(name)) throw new Error(`${where}:${line}: duplicate joint name ${name}`);
    names.push(name); parents.push(parent); offsets.push(null); channels.push([]); end.push(isEnd);
    stack.push(names.length - 1);
  };
  open(-1, false, next("the root's name")[0], root[1]);
  while (stack.length) {
    const j = stack[stack.length - 1];
    const [tok, line] = next("OFFSET, CHANNELS, JOINT, End Site or '}'");
    const key = tok.toUpperCase();
    if (key === "OFFSET") {
      offsets[j] = [0, 1, 2].map(() => number(next("an OFFSET number"), where, "OFFSET"));
    } else if (key === "CHANNELS") {
      const n = Number(next("the channel count")[0]);
      if (!Number.isInteger(n) || n < 0 || n > 6) throw new Error(`${where}:${line}: CHANNELS: expected 0 to 6 channels`);
      for (let c = 0; c < n; c++) {
        const ch = next("a channel name");
        if (!CHANNELS.includes(ch[0].toLowerCase())) throw new Error(`${where}:${ch[1]}: unknown channel ${JSON.stringify(ch[0].slice(0, 30))}`);
        channels[j].push(ch[0].toLowerCase());
      }
    } else if (key === "JOINT") {
      if (offsets[j] === null) throw new Error(`${where}:${line}: missing OFFSET for ${names[j]}`);
      open(j, false, next("a joint name")[0], line);
    } else if (key === "END") {
      next("'Site'");
      open(j, true, `${names[j]}_end`, line);
    } else if (key === "}") {
      if (offsets[j] === null) throw new Error(`${where}:${line}: missing OFFSET for ${names[j]}`);
      stack.pop();
    } else {
      throw new Error(`${where}:${line}: unexpected ${JSON.stringify(tok.slice(0, 30))} in the block of ${names[j]}`);
    }
  }
  if (k < toks.length) throw new Error(`${where}:${toks[k][1]}: unexpected ${JSON.stringify(toks[k][0].slice(0, 30))} after the hierarchy`);
  const rest = text.slice(m.index + m[0].length).split("\n");
  let li = 0;
  const line = (what) => {
    while (li < rest.length && !rest[li].trim()) li++;
    if (li >= rest.length) throw new Error(`${where}: missing ${what}`);
    return [rest[li++].trim(), headLines + li];
  };
  const [fl, fn] = line("Frames:");
  const fm = /^Frames:\s*(\d+)$/i.exec(fl);
  if (!fm) throw new Error(`${where}:${fn}: expected 'Frames: N', got ${JSON.stringify(fl.slice(0, 40))}`);
  const [tl, tn] = line("Frame Time:");
  const tm = /^Frame\s+Time:\s*(\S+)$/i.exec(tl);
  const frameTime = tm ? Number(tm[1]) : NaN;
  if (!(frameTime > 0 && Number.isFinite(frameTime))) throw new Error(`${where}:${tn}: expected 'Frame Time: SECONDS' (positive)`);
  const F = Number(fm[1]);
  const C = channels.reduce((a, c) => a + c.length, 0);
  if (F * C > MAX_VALUES) throw new Error(`${where}:${fn}: ${F} frames x ${C} channels is more than ${MAX_VALUES} values`);
  if (F < 1) throw new Error(`${where}:${fn}: no frames`);
  const moved = channels.some((c, j) => j > 0 && c.some((n) => n.endsWith("position")));
  if (moved) throw new Error(`${where}: position channels on joints other than the root (not read by the page)`);
  const rot = [], pos = [];
  for (let f = 0; f < F; f++) {
    const [row, rn] = line(`frame ${f + 1} of ${F} (truncated file?)`);
    const vals = row.split(/\s+/);
    if (vals.length !== C) throw new Error(`${where}:${rn}: expected ${C} values (the channels), got ${vals.length}`);
    const v = vals.map((s) => Number(s));
    if (!v.every(Number.isFinite)) throw new Error(`${where}:${rn}: a value that is not a finite number`);
    let c = 0;
    const fr = [];
    let p = offsets[0].slice();
    for (let j = 0; j < names.length; j++) {
      const ang = {}, order = [];
      const pp = [null, null, null];
      for (const ch of channels[j]) {
        if (ch.endsWith("rotation")) { ang[ch[0]] = v[c] * Math.PI / 180; order.push(ch[0]); }
        else pp["xyz".indexOf(ch[0])] = v[c];
        c++;
      }
      if (j === 0 && pp.some((x) => x !== null)) p = pp.map((x) => (x === null ? 0 : x));
      if (order.length) {
        for (const a of "xyz") if (!order.includes(a)) order.push(a);
        fr.push(quatFromEuler(order.map((a) => ang[a] || 0), order.join("")));
      } else fr.push([1, 0, 0, 0]);
    }
    rot.push(fr); pos.push(p);
  }
  return { names, parents, offsets, channels, end, frameTime, rot: quatFix(rot), pos };
}

// BVH text of a clip on a skeleton {names, parents, offsets}: root Xposition Yposition Zposition, every joint
// Zrotation Yrotation Xrotation, an End Site (zero offset) under each leaf.
export function writeBvh(skeleton, rot, pos, frameTime) {
  const { names, parents, offsets } = skeleton;
  const kids = names.map((_, j) => parents.map((p, c) => (p === j ? c : -1)).filter((c) => c >= 0));
  const out = ["HIERARCHY"];
  const f6 = (x) => x.toFixed(6);
  const emit = (j, depth) => {
    const pad = "\t".repeat(depth);
    out.push(`${pad}${j === 0 ? "ROOT" : "JOINT"} ${names[j]}`, `${pad}{`);
    out.push(`${pad}\tOFFSET ${offsets[j].map(f6).join(" ")}`);
    out.push(`${pad}\tCHANNELS ${j === 0 ? "6 Xposition Yposition Zposition " : "3 "}Zrotation Yrotation Xrotation`);
    if (!kids[j].length) out.push(`${pad}\tEnd Site`, `${pad}\t{`, `${pad}\t\tOFFSET 0.000000 0.000000 0.000000`, `${pad}\t}`);
    for (const c of kids[j]) emit(c, depth + 1);
    out.push(`${pad}}`);
  };
  emit(0, 0);
  const order = [];
  const visit = (j) => { order.push(j); kids[j].forEach(visit); };
  visit(0);
  out.push("MOTION", `Frames: ${rot.length}`, `Frame Time: ${frameTime.toFixed(8)}`);
  for (let f = 0; f < rot.length; f++) {
    const row = pos[f].map(f6);
    for (const j of order) row.push(...eulerZYXDegrees(rot[f][j]).map((a) => a.toFixed(6)));
    out.push(row.join(" "));
  }
  return out.join("\n") + "\n";
}

// A .npy file (ArrayBuffer) -> {shape, data: Float64Array}; little-endian float32 / float64, C order only.
export function parseNpy(buffer, where = "array.npy") {
  const bytes = new Uint8Array(buffer);
  const magic = String.fromCharCode(...bytes.slice(0, 6));
  if (magic !== "\x93NUMPY") throw new Error(`${where}: not a .npy file`);
  const major = bytes[6];
  const view = new DataView(buffer);
  const hlen = major === 1 ? view.getUint16(8, true) : view.getUint32(8, true);
  const start = major === 1 ? 10 : 12;
  const header = new TextDecoder().decode(bytes.slice(start, start + hlen));
  const descr = /'descr':\s*'([^']+)'/.exec(header), order = /'fortran_order':\s*(True|False)/.exec(header);
  const shape = /'shape':\s*\(([^)]*)\)/.exec(header);
  if (!descr || !order || !shape || order[1] === "True") throw new Error(`${where}: unsupported .npy header`);
  const dims = shape[1].split(",").map((s) => s.trim()).filter(Boolean).map(Number);
  const n = dims.reduce((a, b) => a * b, 1);
  const off = start + hlen;
  let data;
  if (descr[1] === "<f4") data = Float64Array.from(new Float32Array(buffer.slice(off, off + 4 * n)));
  else if (descr[1] === "<f8") data = new Float64Array(buffer.slice(off, off + 8 * n));
  else throw new Error(`${where}: dtype ${descr[1]} (expected <f4 or <f8)`);
  if (data.length !== n) throw new Error(`${where}: truncated data`);
  return { shape: dims, data };
}

// Exp-map text: rows of 3 (1 + J) numbers (root position, then each joint's rotation vector v) ->
// {rot: F x J x 4 = quat_fix(quat_from_axis_angle(-v)), pos: F x 3}.
export function parseExpmap(text, joints, where = "clip.txt") {
  if (text.length > MAX_BYTES) throw new Error(`${where}: larger than ${MAX_BYTES / 1048576} MB`);
  const width = 3 * (1 + joints);
  const rows = [];
  const lines = text.replace(/\r\n?/g, "\n").split("\n");
  for (let i = 0; i < lines.length; i++) {
    const t = lines[i].replace(/,/g, " ").trim();
    if (!t) continue;
    const v = t.split(/\s+/).map(Number);
    if (v.length !== width) throw new Error(`${where}:${i + 1}: expected ${width} values, got ${v.length}`);
    if (!v.every(Number.isFinite)) throw new Error(`${where}:${i + 1}: a value that is not a finite number`);
    rows.push(v);
  }
  if (!rows.length) throw new Error(`${where}:1: empty file (expected rows of ${width} values)`);
  const rot = rows.map((r) => {
    const fr = [];
    for (let j = 0; j < joints; j++) {
      const v = [-r[3 + 3 * j], -r[4 + 3 * j], -r[5 + 3 * j]];
      const half = 0.5 * Math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
      const s = half < 1e-4 ? 0.5 * (1 - half * half / 6 + half ** 4 / 120) : 0.5 * Math.sin(half) / half;
      fr.push([Math.cos(half), s * v[0], s * v[1], s * v[2]]);
    }
    return fr;
  });
  return { rot: quatFix(rot), pos: rows.map((r) => r.slice(0, 3)) };
}
