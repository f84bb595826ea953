// The page: three views (QTG transitions, the long-term walker, QuaterNet short-term) over the served model
// folders (/models/manifest.json). Every failure is one line in #message; nothing leaves this origin.
// window.refimplWeb exposes the last results (for the browser test and the curious).
import { forwardKinematics } from "./math.js";
import { parseBvh, parseNpy, writeBvh } from "./formats.js";
import { fetchBytes, fetchJson, requireModel, session, tensor } from "./models.js";
import { RIG_UNIT_CM, clipForModel, transition } from "./qtg.js";
import { FPS, QUATERNET_UNIT_CM, parseSpeed, paceTracks, pathFromMetres, roundHalfEven, walkPath } from "./walk.js";
import { clipForPredictor, continueClip } from "./quaternet.js";
import { Player, Stage } from "./view.js";

const $ = (id) => document.getElementById(id);
const api = { results: {}, messages: [], manifest: null, busy: false };
window.refimplWeb = api;

function message(text, ok = false) {
  const line = String(text).split("\n")[0].slice(0, 300);
  $("message").textContent = line;
  $("message").className = ok ? "ok" : "";
  api.messages.push({ text: line, ok });
}
const fail = (err) => message(`error: ${err && err.message ? err.message : err}`);
window.addEventListener("error", (e) => fail(e.error || e.message));
window.addEventListener("unhandledrejection", (e) => fail(e.reason));

async function guarded(button, work) {
  if (api.busy) return;
  api.busy = true;
  button.disabled = true;
  try { await work(); } catch (err) { fail(err); } finally { api.busy = false; button.disabled = false; }
}

const stage = new Stage($("stage"));
api.stage = stage;
let frames = [];
const player = new Player({ play: $("play"), scrub: $("scrub"), label: $("frame-label"), bar: $("bar") }, (i) => stage.show(frames[i]));
function load(newFrames, fps, marks) { frames = newFrames; player.load(frames.length, fps, marks); }

// ---------------------------------------------------------------------------------------------- folders
function fillFolders(select, model) {
  const folders = api.manifest.folders;
  select.innerHTML = "";
  folders.forEach((f) => select.add(new Option(`${f.label} (${f.model})`, String(f.id))));
  const first = folders.find((f) => f.model === model);
  if (first) select.value = String(first.id);
}
const folderOf = (select) => api.manifest.folders.find((f) => String(f.id) === select.value);

// ---------------------------------------------------------------------------------------------- QTG
const clips = new Map();           // name -> {text} | {bvh}
async function bvhOf(name) {
  const c = clips.get(name);
  if (!c) throw new Error(`no clip ${name}`);
  if (!c.bvh) c.bvh = parseBvh(c.text ?? new TextDecoder().decode(await fetchBytes(c.url)), name);
  return c.bvh;
}
function addClip(name, entry) {
  clips.set(name, entry);
  for (const id of ["qtg-source-clip", "qtg-target-clip"]) {
    if (![...$(id).options].some((o) => o.value === name)) $(id).add(new Option(name, name));
  }
}
async function addFile(file) {
  if (!/\.bvh$/i.test(file.name)) throw new Error(`${file.name}: expected a .bvh file`);
  if (file.size > 64 * 1024 * 1024) throw new Error(`${file.name}: larger than 64 MB`);
  const text = await file.text();
  const bvh = parseBvh(text, file.name);          // a malformed file is refused here, before it is listed
  addClip(file.name, { text, bvh });
  $("qtg-source-clip").value = file.name; $("qtg-target-clip").value = file.name;
  message(`added ${file.name}: ${bvh.rot.length} frames, ${bvh.names.length} joints`, true);
}

function rolloutOf(sess, meta) {
  const P = meta.skeleton.names.length * 4 + 3, norm = meta.normalization;
  const scale = norm && !norm.in_graph ? [norm.mean.slice(0, 3), norm.std.slice(0, 3)] : null;
  const prep = (rows) => rows.map((r) => (scale ? r.map((v, i) => (i < 3 ? (v - scale[0][i]) / scale[1][i] : v)) : r)).flat();
  return async (past, target) => {
    const out = await sess.run({ past: tensor(prep(past), [1, 2, P]), target: tensor(prep(target), [1, 2, P]) });
    const y = out.poses.data, T = out.poses.dims[1], rows = [];
    for (let t = 0; t < T; t++) {
      const r = Array.from(y.subarray(t * P, (t + 1) * P));
      rows.push(scale ? r.map((v, i) => (i < 3 ? v * scale[1][i] + scale[0][i] : v)) : r);
    }
    return rows;
  };
}

async function runQtg() {
  const folder = folderOf($("qtg-folder"));
  requireModel(folder, "qtg", ["qtg_rollout.onnx"]);
  const meta = folder.metadata["qtg_rollout.onnx"];
  const T = meta.model.transition_length, fps = meta.frame_rate, unit = RIG_UNIT_CM[$("qtg-units").value];
  const srcName = $("qtg-source-clip").value, tgtName = $("qtg-target-clip").value;
  const src = clipForModel(await bvhOf(srcName), meta.skeleton, unit, fps, srcName);
  const tgt = srcName === tgtName ? src : clipForModel(await bvhOf(tgtName), meta.skeleton, unit, fps, tgtName);
  const s = Number($("qtg-source-frame").value), g = Number($("qtg-target-frame").value);
  const sess = await session(folder, "qtg_rollout.onnx");
  const tr = await transition(rolloutOf(sess, meta), T, src, s, tgt, g, { align: $("qtg-align").value, sameClip: srcName === tgtName });
  const sk = src.skeleton;
  stage.setFigures([sk]); stage.setPath(null);
  load(tr.rot.map((q, i) => [{ pos: forwardKinematics(sk.parents, sk.offsets, q, tr.pos[i]), generated: i >= tr.start && i < tr.stop }]), fps, [[tr.start, tr.stop]]);
  stage.setGhosts(sk.parents, [frames[tr.start - 1][0].pos, frames[Math.min(tr.stop, frames.length - 1)][0].pos]);
  player.go(tr.start + Math.floor(T / 2));
  api.results.qtg = { ...tr, skeleton: sk, fps, T };
  $("qtg-download").disabled = false;
  message(`generated ${T} frames between ${srcName} frame ${s} and ${tgtName} frame ${g} (join: ${joinOf(meta)}); yellow trunk = generated, grey lines = the join frames`, true);
}

const joinOf = (meta) => (meta.join ? (typeof meta.join === "object" ? `${meta.join.mode ?? "on"}${meta.join.blend_frames ? ` (${meta.join.blend_frames} blend frames)` : ""}` : String(meta.join)) : "none");

function downloadQtg() {
  const r = api.results.qtg;
  if (!r) throw new Error("generate a transition first");
  const text = writeBvh(r.skeleton, r.rot, r.pos, 1 / r.fps);
  api.results.qtgBvh = text;
  const a = document.createElement("a");
  a.href = URL.createObjectURL(new Blob([text], { type: "text/plain" }));
  a.download = "transition.bvh";
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

// ---------------------------------------------------------------------------------------------- walker
const pad = $("walk-pad"), HALF = 10;   // metres from the centre of the pad to its edge
let drawn = [];
const toMetres = (e) => { const r = pad.getBoundingClientRect(); return [((e.clientX - r.left) / r.width * 2 - 1) * HALF, ((e.clientY - r.top) / r.height * 2 - 1) * HALF]; };
function drawPad() {
  const c = pad.getContext("2d"), w = pad.width, px = (m) => ((m / HALF) + 1) * w / 2;
  c.clearRect(0, 0, w, w);
  c.strokeStyle = "#ddd";
  for (let m = -HALF; m <= HALF; m += 2) { c.beginPath(); c.moveTo(px(m), 0); c.lineTo(px(m), w); c.moveTo(0, px(m)); c.lineTo(w, px(m)); c.stroke(); }
  c.strokeStyle = "#1a9e55"; c.lineWidth = 2; c.beginPath();
  drawn.forEach((p, i) => (i ? c.lineTo(px(p[0]), px(p[1])) : c.moveTo(px(p[0]), px(p[1]))));
  c.stroke();
  if (drawn.length) { c.fillStyle = "#1a9e55"; c.fillRect(px(drawn[0][0]) - 3, px(drawn[0][1]) - 3, 6, 6); }
}
let drawing = false;
pad.addEventListener("pointerdown", (e) => { drawing = true; drawn = [toMetres(e)]; drawPad(); });
pad.addEventListener("pointermove", (e) => {
  if (!drawing) return;
  const p = toMetres(e), q = drawn[drawn.length - 1];
  if (Math.hypot(p[0] - q[0], p[1] - q[1]) >= 0.1) { drawn.push(p); drawPad(); }
});
window.addEventListener("pointerup", () => { drawing = false; });
api.setPath = (points) => { drawn = points.map((p) => p.slice()); drawPad(); };
api.path = () => drawn.map((p) => p.slice());

function walkFolders() {
  const folder = folderOf($("walk-folder"));
  requireModel(folder, "quaternet-long", ["quaternet-long_step.onnx", "quaternet-long_h0.npy", "quaternet-long_seed.npy"]);
  const pace = folder.files.includes("quaternet-long_pace.onnx") ? folder
    : api.manifest.folders.find((f) => f.model === "quaternet-long" && f.files.includes("quaternet-long_pace.onnx"));
  if (!pace) throw new Error(`folder ${folder.label} has no quaternet-long_pace.onnx and no served folder has one (export the pace checkpoint too)`);
  return [folder, pace];
}

async function runWalk() {
  const points = drawn.map((p) => p.slice());
  const path = pathFromMetres(points);
  const speed = parseSpeed($("walk-speed").value);
  const seconds = Number($("walk-seconds").value);
  if (!(seconds >= 0.1 && seconds <= 60)) throw new Error(`seconds: expected 0.1 ... 60, got ${$("walk-seconds").value}`);
  const [folder, paceFolder] = walkFolders();
  const meta = folder.metadata["quaternet-long_step.onnx"], paceMeta = paceFolder.metadata["quaternet-long_pace.onnx"];
  if ((meta.representation || {}).kind === "quaternet_long_dq") throw new Error("a dual-quaternion long-term model: the page walks the quaternion one only");
  const J = meta.skeleton.names.length;
  const [stepS, paceS] = [await session(folder, "quaternet-long_step.onnx"), await session(paceFolder, "quaternet-long_pace.onnx")];
  const h0 = parseNpy(await fetchBytes(`/models/${folder.id}/quaternet-long_h0.npy`), "quaternet-long_h0.npy");
  const seedArr = parseNpy(await fetchBytes(`/models/${folder.id}/quaternet-long_seed.npy`), "quaternet-long_seed.npy");
  const width = seedArr.shape[1];
  if (width !== 4 * J + 8) throw new Error(`quaternet-long_seed.npy has frames of ${width} values, expected ${4 * J + 8}`);
  const seed = [];
  for (let t = 0; t < seedArr.shape[0]; t++) seed.push(Array.from(seedArr.data.subarray(t * width, (t + 1) * width)));
  const pace = async (x, n) => {
    const y = (await paceS.run({ x: tensor(x, [1, n, 2]) })).y.data;
    return Array.from({ length: n }, (_, i) => Array.from(y.subarray(4 * i, 4 * i + 4)));
  };
  const tracks = await paceTracks(pace, path, speed, (paceMeta.representation || {}).points_per_unit ?? 5);
  const step = async (x, h) => {
    const out = await stepS.run({ x: tensor(x, [1, x.length]), state: h });
    return { y: out.y.data, state: out.state_next };
  };
  const cm = QUATERNET_UNIT_CM, sk = { ...meta.skeleton, offsets: meta.skeleton.offsets.map((o) => o.map((v) => v * cm)) };
  stage.setFigures([sk]); stage.setGhosts(sk.parents, []);
  stage.setPath(points.map((p) => [p[0] * 100, p[1] * 100]));
  const out = [], shown = [], t0 = performance.now(), N = roundHalfEven(seconds * FPS);
  frames = shown;
  for await (const f of walkPath(step, tensor(Float32Array.from(h0.data), h0.shape), tracks, J, seed, N)) {
    out.push([...f.rot.flat(), ...f.root]);
    const root = f.root.map((v) => v * cm);
    shown.push([{ pos: forwardKinematics(sk.parents, sk.offsets, f.rot, root), generated: true }]);
    if (shown.length % 5 === 1 || shown.length === N) { player.load(shown.length, FPS, [[0, shown.length]]); player.go(shown.length - 1); }
    const wait = (out.length * 1000) / FPS - (performance.now() - t0);   // live: at most real time
    await new Promise((r) => setTimeout(r, Math.max(0, wait)));
  }
  player.load(shown.length, FPS, [[0, shown.length]]); player.go(shown.length - 1);
  api.results.walk = { frames: out, points, speed, seconds };
  message(`walked ${out.length} frames (${(out.length / FPS).toFixed(1)} s) along a ${(path.length * cm / 100).toFixed(1)} m path at ${speed} units per frame`, true);
}

// ---------------------------------------------------------------------------------------------- QuaterNet
async function runQn() {
  const folder = folderOf($("qn-folder"));
  requireModel(folder, "quaternet", ["quaternet_predict.onnx"]);
  const meta = folder.metadata["quaternet_predict.onnx"];
  if (meta.representation.name !== "quaternet_frame") throw new Error(`a ${meta.representation.name} model: the page continues quaternion QuaterNet models only`);
  const P = meta.prefix_length, name = $("qn-clip").value;
  const sample = api.manifest.samples.find((s) => s.name === name);
  const rot = clipForPredictor(new TextDecoder().decode(await fetchBytes(sample.url)), meta, name);
  const sess = await session(folder, "quaternet_predict.onnx");
  const F = 4 * meta.skeleton.names.length;
  const predict = async (x, n) => {
    const y = (await sess.run({ prefix: tensor(x, [1, n, F]) })).frames;
    return Array.from({ length: y.dims[1] }, (_, t) => Array.from(y.data.subarray(t * F, (t + 1) * F)));
  };
  const frame = Number($("qn-frame").value);
  const r = await continueClip(predict, rot, frame, P);
  const cm = QUATERNET_UNIT_CM, sk = { ...meta.skeleton, offsets: meta.skeleton.offsets.map((o) => o.map((v) => v * cm)) };
  const lift = -Math.min(...forwardKinematics(sk.parents, sk.offsets, r.prefix[0], [0, 0, 0]).map((p) => p[1]));
  const fk = (q, x) => forwardKinematics(sk.parents, sk.offsets, q, [x, lift, 0]);
  const truth = [...r.prefix, ...r.truth], pred = [...r.prefix, ...r.pred];
  stage.setFigures([sk, sk]); stage.setPath(null); stage.setGhosts(sk.parents, []);
  stage.follow = false;
  stage.lookAt(0, lift, 0);
  load(pred.map((q, i) => [{ pos: fk(truth[Math.min(i, truth.length - 1)], -80), generated: false }, { pos: fk(q, 80), generated: i >= P }]), meta.frame_rate, [[P, pred.length]]);
  player.go(P - 1);
  api.results.qn = { pred: r.pred, frame, P };
  message(`predicted frames ${frame + 1} ... ${frame + r.pred.length} of ${name} from the ${P} frames ending at ${frame} (left: ground truth)`, true);
}

// ---------------------------------------------------------------------------------------------- start
function showView(view) {
  for (const b of document.querySelectorAll(".tab")) b.classList.toggle("active", b.dataset.view === view);
  for (const v of ["qtg", "walk", "qn"]) $(`panel-${v}`).hidden = v !== view;
  stage.follow = view !== "qn";
  api.view = view;
}

function describe(select, id, file) {
  const f = folderOf(select);
  const m = f && f.metadata[file];
  $(id).textContent = f ? `${f.path}: ${f.model}${m ? `, ${m.frame_rate} fps` : ""}${m && file === "qtg_rollout.onnx" ? `, T = ${m.model.transition_length}, join ${joinOf(m)}` : ""}` : "";
}

async function start() {
  api.manifest = await fetchJson("/models/manifest.json");
  fillFolders($("qtg-folder"), "qtg"); fillFolders($("walk-folder"), "quaternet-long"); fillFolders($("qn-folder"), "quaternet");
  for (const s of api.manifest.samples) {
    if (s.kind === "bvh") addClip(s.name, { url: s.url });
    else $("qn-clip").add(new Option(s.name, s.name));
  }
  const watch = [["qtg-folder", "qtg-meta", "qtg_rollout.onnx"], ["walk-folder", "walk-meta", "quaternet-long_step.onnx"], ["qn-folder", "qn-meta", "quaternet_predict.onnx"]];
  for (const [sel, id, file] of watch) { $(sel).addEventListener("change", () => describe($(sel), id, file)); describe($(sel), id, file); }
  for (const b of document.querySelectorAll(".tab")) b.addEventListener("click", () => showView(b.dataset.view));
  $("qtg-run").addEventListener("click", () => guarded($("qtg-run"), runQtg));
  $("qtg-download").addEventListener("click", () => { try { downloadQtg(); } catch (e) { fail(e); } });
  $("qtg-file").addEventListener("change", (e) => { const f = e.target.files[0]; if (f) addFile(f).catch(fail); e.target.value = ""; });
  $("walk-run").addEventListener("click", () => guarded($("walk-run"), runWalk));
  $("walk-clear").addEventListener("click", () => { drawn = []; drawPad(); });
  $("qn-run").addEventListener("click", () => guarded($("qn-run"), runQn));
  document.addEventListener("dragover", (e) => { e.preventDefault(); document.body.classList.add("dragging"); });
  document.addEventListener("dragleave", () => document.body.classList.remove("dragging"));
  document.addEventListener("drop", (e) => {
    e.preventDefault(); document.body.classList.remove("dragging");
    const f = e.dataTransfer.files[0];
    if (f) { showView("qtg"); addFile(f).catch(fail); }
  });
  drawPad();
  const n = api.manifest.folders.length;
  $("status").textContent = `${n} model folder${n === 1 ? "" : "s"} · onnxruntime-web (wasm)`;
  if (!n) message("no model folders are served: python -m deploy web DIR (a folder written by python -m deploy export)");
  api.ready = true;
}

start().catch(fail);
