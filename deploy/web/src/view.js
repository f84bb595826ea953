// The 3-D stage: a floor fixed in the world (a grid of 50 cm cells), stick figures with left and right limbs
// in two colours, a player (play, pause, scrub) over frames whose generated part is marked.
// Lengths in centimetres, y up. A frame is [{pos: J x 3, generated: bool}] (one entry per figure).
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";

// Left and right limbs keep their colours in every frame; a generated frame turns the trunk and head yellow.
export const COLOURS = { left: 0x2f6fd0, right: 0xe0533d, centre: 0x6b6b6b, generated: 0xf2b705 };

// -1 left, +1 right, 0 centre, from the joint names (Left*, L*, l*; Right*, R*, r*; *_l, *_r).
export function sideOf(name) {
  if (/^(Left|left|L(?=[A-Z])|l(?=[A-Z]))/.test(name) || /[._][lL]$/.test(name)) return -1;
  if (/^(Right|right|R(?=[A-Z])|r(?=[A-Z]))/.test(name) || /[._][rR]$/.test(name)) return 1;
  return 0;
}

// The floor: a 200 m square at y = 0 with a 1 m grid (a repeated canvas texture: long grid lines crossing the near
// plane are not drawn by every WebGL rasteriser).
function floorMesh() {
  const c = document.createElement("canvas");
  c.width = c.height = 128;
  const g = c.getContext("2d");
  g.fillStyle = "#ecece6"; g.fillRect(0, 0, 128, 128);
  g.strokeStyle = "#d2d2c8"; g.lineWidth = 2; g.strokeRect(64, 64, 64, 64); g.strokeRect(0, 0, 64, 64);
  g.strokeStyle = "#a9a99e"; g.lineWidth = 3; g.strokeRect(0, 0, 128, 128);
  const tex = new THREE.CanvasTexture(c);
  tex.wrapS = tex.wrapT = THREE.RepeatWrapping;
  tex.repeat.set(200, 200);
  tex.anisotropy = 8;
  tex.colorSpace = THREE.SRGBColorSpace;
  const floor = new THREE.Mesh(new THREE.PlaneGeometry(20000, 20000), new THREE.MeshBasicMaterial({ map: tex }));
  floor.rotation.x = -Math.PI / 2;
  return floor;
}

export class Stage {
  constructor(container) {
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(1);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xf4f4f0);
    this.camera = new THREE.PerspectiveCamera(45, 1, 1, 20000);
    this.camera.position.set(230, 190, 300);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(0, 90, 0);
    this.scene.add(floorMesh());
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x888888, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.2); sun.position.set(300, 800, 200); this.scene.add(sun);
    this.figures = [];
    this.extras = new THREE.Group(); this.scene.add(this.extras);
    this.container = container;
    this.follow = true;
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
    // draw only when something moved (a software WebGL costs a core per continuous redraw)
    this.dirty = true;
    this.controls.addEventListener("change", () => { this.dirty = true; });
    const loop = () => {
      this.controls.update();
      if (this.dirty) { this.dirty = false; this.renderer.render(this.scene, this.camera); }
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  resize() {
    const w = Math.max(200, this.container.clientWidth), h = Math.max(200, this.container.clientHeight);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h; this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  // Figures for skeletons [{names, parents}], replacing the old ones.
  setFigures(skeletons) {
    for (const f of this.figures) this.scene.remove(f.group);
    this.figures = skeletons.map((sk) => {
      const group = new THREE.Group();
      const bones = [];
      const mats = { "-1": new THREE.MeshLambertMaterial({ color: COLOURS.left }), 1: new THREE.MeshLambertMaterial({ color: COLOURS.right }), 0: new THREE.MeshLambertMaterial({ color: COLOURS.centre }) };
      const gen = new THREE.MeshLambertMaterial({ color: COLOURS.generated });
      sk.parents.forEach((p, j) => {
        if (p < 0) return;
        const side = sideOf(sk.names[j]);
        const m = new THREE.Mesh(new THREE.CylinderGeometry(2.2, 2.2, 1, 8), mats[side]);
        m.userData = { j, p, mat: mats[side], side };
        group.add(m); bones.push(m);
      });
      const head = new THREE.Mesh(new THREE.SphereGeometry(4, 12, 8), mats[0]);
      group.add(head);
      this.scene.add(group);
      return { group, bones, gen, head, mats };
    });
  }

  // Pose the figures: frame = [{pos, generated}] in the order of setFigures.
  show(frame) {
    this.dirty = true;
    const up = new THREE.Vector3(0, 1, 0);
    frame.forEach((f, i) => {
      const fig = this.figures[i];
      if (!fig) return;
      for (const b of fig.bones) {
        const a = new THREE.Vector3(...f.pos[b.userData.p]), c = new THREE.Vector3(...f.pos[b.userData.j]);
        const d = c.clone().sub(a), len = d.length();
        b.visible = len > 1e-6;
        b.position.copy(a).addScaledVector(d, 0.5);
        b.scale.set(1, Math.max(len, 1e-6), 1);
        if (len > 1e-6) b.quaternion.setFromUnitVectors(up, d.normalize());
        b.material = f.generated && b.userData.side === 0 ? fig.gen : b.userData.mat;
      }
      const top = f.pos.reduce((m, p) => (p[1] > m[1] ? p : m), f.pos[0]);
      fig.head.position.set(...top);
      fig.head.material = f.generated ? fig.gen : fig.mats[0];
    });
    if (this.follow && frame.length) {
      const r = frame[0].pos[0];
      const t = this.controls.target, dx = r[0] - t.x, dz = r[2] - t.z;
      t.x += dx; t.z += dz; this.camera.position.x += dx; this.camera.position.z += dz;
    }
  }

  // Faded still poses (e.g. the join frames: the last source and the first target frame), lines only.
  setGhosts(parents, poses) {
    if (this.ghosts) this.scene.remove(this.ghosts);
    this.ghosts = new THREE.Group();
    for (const pos of poses || []) {
      const pts = [];
      parents.forEach((p, j) => { if (p >= 0) pts.push(new THREE.Vector3(...pos[p]), new THREE.Vector3(...pos[j])); });
      const g = new THREE.BufferGeometry().setFromPoints(pts);
      this.ghosts.add(new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: 0x555555, transparent: true, opacity: 0.45 })));
    }
    this.scene.add(this.ghosts);
    this.dirty = true;
  }

  // Point the camera at (x, y, z) from the default offset.
  lookAt(x, y, z) {
    this.controls.target.set(x, y, z);
    this.camera.position.set(x + 230, y + 100, z + 300);
    this.dirty = true;
  }

  // A polyline on the floor (points [x, z] in cm).
  setPath(points, colour = 0x1a9e55) {
    this.extras.clear();
    this.dirty = true;
    if (!points || points.length < 2) return;
    const g = new THREE.BufferGeometry().setFromPoints(points.map((p) => new THREE.Vector3(p[0], 0.5, p[1])));
    this.extras.add(new THREE.Line(g, new THREE.LineBasicMaterial({ color: colour })));
  }
}

// Play, pause and scrub over `frames` at `fps`; `onFrame(i)` shows frame i. The range [start, stop) of
// generated frames is marked on the timeline.
export class Player {
  constructor({ play, scrub, label, bar }, onFrame) {
    Object.assign(this, { playBtn: play, scrub, label, bar, onFrame, n: 0, i: 0, fps: 30, playing: false, marks: [] });
    play.addEventListener("click", () => this.toggle());
    scrub.addEventListener("input", () => { this.pause(); this.go(Number(scrub.value)); });
    let last = null;
    const tick = (t) => {
      if (this.playing && this.n > 1) {
        if (last === null) last = t;
        const step = Math.floor(((t - last) / 1000) * this.fps);
        if (step > 0) { last += (step * 1000) / this.fps; this.go((this.i + step) % this.n); }
      } else last = null;
      requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  }

  load(n, fps, marks = []) {
    Object.assign(this, { n, fps, marks });
    this.scrub.max = String(Math.max(0, n - 1));
    this.bar.innerHTML = "";
    for (const [a, b] of marks) {
      const d = document.createElement("div");
      d.className = "mark";
      d.style.left = `${(100 * a) / Math.max(1, n - 1)}%`;
      d.style.width = `${(100 * Math.max(0, b - 1 - a)) / Math.max(1, n - 1)}%`;
      this.bar.appendChild(d);
    }
    this.go(0);
  }

  go(i) {
    this.i = Math.max(0, Math.min(this.n - 1, i));
    this.scrub.value = String(this.i);
    const gen = this.marks.some(([a, b]) => this.i >= a && this.i < b);
    this.label.textContent = this.n ? `frame ${this.i} / ${this.n - 1}${gen ? " · generated" : ""}` : "";
    if (this.n) this.onFrame(this.i);
  }

  toggle() { this.playing ? this.pause() : this.play(); }
  play() { this.playing = true; this.playBtn.textContent = "Pause"; }
  pause() { this.playing = false; this.playBtn.textContent = "Play"; }
}
