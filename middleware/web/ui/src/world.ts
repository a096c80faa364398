// The world view: the simulator's car on its road, drawn from the stream's `world`
// messages (a channel apart from the bus's signals: the gateway never sees it). Top-down
// (north up, following the car) or a chase view from behind; poses come at 20 Hz and are
// interpolated to the display's frame rate. Plain canvas 2D, written here: a 3D library
// would cost more of the first-load budget than a road of quads and a box need.
import { h, setText } from './util';
import type { Live } from './live';

/** A pose as the channel sends it: [t, x, y, heading, speed, steer, marks]. */
type Pose = [number, number, number, number, number, number, number];

interface Patch { name: string; mu: number; outline: [number, number][] }
interface Road { name: string; width_m: number; closed: boolean; length_m: number; centre: [number, number, number][]; patches: Patch[]; verge_mu: number }
interface Car { length_m: number; width_m: number; cg_to_front_m: number; wheels: [number, number][]; wheel_radius_m: number }
interface Description { road: Road | null; car: Car }

/** Poses kept for the path (the channel keeps 2 minutes; the path keeps longer, thinned). */
const MAX_PATH = 6000;
/** A car that moved this far between two poses (50 ms) was put somewhere, not driven, m. */
const JUMP_M = 30;
/** Tyre-mark points kept per wheel. */
const MAX_MARKS = 4000;
/** The view runs this far behind the newest pose, s: one update period, so that there is
 *  always a pose on either side to interpolate between. */
const DELAY_S = 0.06;

/** The world as the stream has told it. */
export class World {
  description: Description | null = null;
  poses: Pose[] = [];
  path: [number, number][] = [];
  /** Per wheel: runs of mark points (a run ends where the wheel stopped marking). */
  marks: [number, number][][][] = [[], [], [], []];
  private markCount = 0;
  /** Wall time (ms) at which the newest pose arrived, and the rate simulated time runs at
   *  against the wall (1 live, the replay's speed in a replay). */
  arrived = 0;
  rate = 1;
  /** Bumped when the world is described anew (a view rebuilds its road). */
  generation = 0;

  take(message: any): void {
    if (message.description !== undefined) {
      this.description = message.description;
      this.poses = [];
      this.path = [];
      this.marks = [[], [], [], []];
      this.markCount = 0;
      this.generation++;
    }
    const now = performance.now();
    const poses: Pose[] = (message.poses ?? []).filter((p: any) => Array.isArray(p) && p.length === 7 && p.every((v: any) => typeof v === 'number' && isFinite(v)));
    if (poses.length === 0) return;
    const previous = this.poses[this.poses.length - 1];
    for (const pose of poses) this.add(pose);
    const last = poses[poses.length - 1];
    if (previous && this.arrived > 0 && message.description === undefined) {
      const wall = (now - this.arrived) / 1000;
      const sim = last[0] - previous[0];
      if (wall > 0.01 && sim >= 0) this.rate = Math.max(0, Math.min(50, 0.8 * this.rate + 0.2 * (sim / wall)));
    }
    this.arrived = now;
  }

  private add(pose: Pose): void {
    const last = this.poses[this.poses.length - 1];
    const jumped = last && Math.hypot(pose[1] - last[1], pose[2] - last[2]) > JUMP_M;
    if (last && (pose[0] < last[0] || jumped)) {
      // Time went back (a replay's seek) or the car was taken back to the start: the old
      // path no longer leads here.
      this.poses = [];
      this.path = [];
      this.marks = [[], [], [], []];
      this.markCount = 0;
    }
    this.poses.push(pose);
    if (this.poses.length > 2400) this.poses.splice(0, this.poses.length - 2400);
    const p = this.path[this.path.length - 1];
    if (!p || Math.hypot(pose[1] - p[0], pose[2] - p[1]) > 0.5) {
      this.path.push([pose[1], pose[2]]);
      if (this.path.length > MAX_PATH) this.path.splice(0, this.path.length - MAX_PATH);
    }
    const car = this.description?.car;
    if (!car) return;
    const prev = last?.[6] ?? 0;
    for (let i = 0; i < 4; i++) {
      const on = (pose[6] >> i) & 1;
      if (!on) continue;
      const [wx, wy] = car.wheels[i];
      const c = Math.cos(pose[3]), s = Math.sin(pose[3]);
      const point: [number, number] = [pose[1] + wx * c - wy * s, pose[2] + wx * s + wy * c];
      const runs = this.marks[i];
      if (!((prev >> i) & 1) || runs.length === 0) runs.push([]);
      runs[runs.length - 1].push(point);
      this.markCount++;
    }
    while (this.markCount > 4 * MAX_MARKS) {
      const longest = this.marks.reduce((a, b) => (a.length >= b.length ? a : b));
      const dropped = longest.shift();
      this.markCount -= dropped?.length ?? 0;
      if (!dropped) break;
    }
  }

  /** The pose at wall time `now` (ms): interpolated between the two around it. */
  poseAt(now: number): Pose | null {
    const n = this.poses.length;
    if (n === 0) return null;
    const newest = this.poses[n - 1];
    const t = newest[0] - DELAY_S * Math.max(this.rate, 0.05) + Math.min(0.25, (now - this.arrived) / 1000) * this.rate;
    if (t >= newest[0]) return newest;
    let i = n - 1;
    while (i > 0 && this.poses[i - 1][0] > t) i--;
    if (i === 0) return this.poses[0];
    const a = this.poses[i - 1], b = this.poses[i];
    const k = b[0] > a[0] ? (t - a[0]) / (b[0] - a[0]) : 1;
    const mix = (j: number) => a[j] + (b[j] - a[j]) * k;
    return [t, mix(1), mix(2), mix(3), mix(4), mix(5), b[6]];
  }
}

type Mode = 'top' | 'chase';

/** The world view's element, drawing the live stream's world while it is in the page. */
export function worldView(live: Live): { el: HTMLElement; destroy(): void } {
  const world = live.world;
  const canvas = h('canvas', { class: 'world-canvas', 'data-testid': 'world-canvas', 'aria-label': 'the car on its road, as the simulator has it' }) as HTMLCanvasElement;
  const info = h('div', { class: 'world-info muted small', 'data-testid': 'world-info' });
  const fpsText = h('span', { class: 'muted small', 'data-testid': 'world-fps' });
  let mode: Mode = (localStorage.getItem('autoplug.world.mode') as Mode) || 'top';
  // 7 px/m: the 4.35 m car some 30 px long, 100 m of road across the view.
  let zoom = Number(localStorage.getItem('autoplug.world.zoom')) || 7;
  const modeButton = (m: Mode, text: string) => {
    const b = h('button', { class: 'btn', 'data-testid': `world-${m}`, onclick: () => { mode = m; localStorage.setItem('autoplug.world.mode', m); buttons(); } }, text);
    return b;
  };
  const top = modeButton('top', 'Top');
  const chase = modeButton('chase', 'Chase');
  const zoomIn = h('button', { class: 'btn', title: 'zoom in', onclick: () => setZoom(zoom * 1.5) }, '+');
  const zoomOut = h('button', { class: 'btn', title: 'zoom out', onclick: () => setZoom(zoom / 1.5) }, '−');
  function setZoom(z: number): void { zoom = Math.max(0.3, Math.min(40, z)); localStorage.setItem('autoplug.world.zoom', String(zoom)); }
  function buttons(): void {
    top.classList.toggle('active', mode === 'top');
    chase.classList.toggle('active', mode === 'chase');
    zoomIn.hidden = zoomOut.hidden = mode !== 'top';
  }
  buttons();
  const el = h('div', { class: 'card world', 'data-testid': 'world' },
    h('div', { class: 'toolbar' }, h('h3', { text: 'World (the simulator, not the bus)' }), h('div', { class: 'buttons' }, top, chase, zoomOut, zoomIn), fpsText),
    h('div', { class: 'world-frame' }, canvas),
    info);

  // Frame rate over the last second, for the page and the tests.
  const frameTimes: number[] = [];
  let raf = 0;
  let lastInfo = 0;
  const frame = (now: number) => {
    raf = requestAnimationFrame(frame);
    frameTimes.push(now);
    while (frameTimes.length && frameTimes[0] < now - 1000) frameTimes.shift();
    const fps = frameTimes.length;
    draw(now);
    if (now - lastInfo > 250) {
      lastInfo = now;
      setText(fpsText, `${fps} frames/s`);
      el.dataset.fps = String(fps);
    }
  };
  raf = requestAnimationFrame(frame);

  function draw(now: number): void {
    const ratio = window.devicePixelRatio || 1;
    const w = canvas.clientWidth, hgt = canvas.clientHeight;
    if (w === 0 || hgt === 0) return;
    if (canvas.width !== Math.round(w * ratio) || canvas.height !== Math.round(hgt * ratio)) {
      canvas.width = Math.round(w * ratio);
      canvas.height = Math.round(hgt * ratio);
    }
    const g = canvas.getContext('2d');
    if (!g) return;
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    const pose = world.poseAt(now);
    const d = world.description;
    if (!d || !pose) {
      g.fillStyle = '#d9dfd2';
      g.fillRect(0, 0, w, hgt);
      g.fillStyle = '#555';
      g.font = '14px sans-serif';
      g.fillText(d ? 'waiting for the car…' : 'no world: this bus is not the virtual car’s', 16, 28);
      setText(info, '');
      return;
    }
    if (mode === 'top') drawTop(g, w, hgt, d, pose);
    else drawChase(g, w, hgt, d, pose);
    // What the tests compare with the simulator's own numbers.
    el.dataset.t = pose[0].toFixed(3);
    el.dataset.x = pose[1].toFixed(2);
    el.dataset.y = pose[2].toFixed(2);
    el.dataset.heading = (pose[3] * 180 / Math.PI).toFixed(2);
    el.dataset.marks = String(world.marks.reduce((n, runs) => n + runs.reduce((m, r) => m + r.length, 0), 0));
    const road = d.road ? `${d.road.name}` : 'open ground';
    setText(info, `${road} · ${(pose[4] * 3.6).toFixed(0)} km/h · heading ${(((pose[3] * 180 / Math.PI) % 360 + 360) % 360).toFixed(0)}° · t ${pose[0].toFixed(1)} s`);
  }

  // ---- top-down, north up, the car in the middle ----
  function drawTop(g: CanvasRenderingContext2D, w: number, hgt: number, d: Description, pose: Pose): void {
    g.fillStyle = d.road ? '#b8cf9c' : '#e4e4e4';
    g.fillRect(0, 0, w, hgt);
    g.save();
    g.translate(w / 2, hgt / 2);
    g.scale(zoom, -zoom);
    g.translate(-pose[1], -pose[2]);
    const view = Math.hypot(w, hgt) / zoom / 2 + 10;
    const near = (x: number, y: number) => Math.abs(x - pose[1]) < view && Math.abs(y - pose[2]) < view;
    if (d.road) drawRoadTop(g, d.road, near);
    else drawGrid(g, pose, view);
    drawMarks(g);
    g.strokeStyle = 'rgba(31,95,191,0.8)';
    g.lineWidth = 1.5 / zoom;
    polyline(g, world.path);
    g.stroke();
    drawCarTop(g, d.car, pose);
    g.restore();
    scaleBar(g, w, hgt);
  }

  function drawRoadTop(g: CanvasRenderingContext2D, road: Road, near: (x: number, y: number) => boolean): void {
    const half = road.width_m / 2;
    const side = (k: number) => road.centre.map(([x, y, hd]) => [x - k * half * Math.sin(hd), y + k * half * Math.cos(hd)] as [number, number]);
    const left = side(1), right = side(-1);
    g.fillStyle = '#8f8f8f';
    // Quads between consecutive centre points, only those near the car.
    g.beginPath();
    for (let i = 1; i < road.centre.length; i++) {
      if (!near(road.centre[i][0], road.centre[i][1])) continue;
      g.moveTo(left[i - 1][0], left[i - 1][1]);
      g.lineTo(left[i][0], left[i][1]);
      g.lineTo(right[i][0], right[i][1]);
      g.lineTo(right[i - 1][0], right[i - 1][1]);
      g.closePath();
    }
    g.fill();
    for (const patch of road.patches) {
      g.fillStyle = patchColour(patch.mu);
      polyline(g, patch.outline);
      g.closePath();
      g.fill();
    }
    g.strokeStyle = '#fff';
    g.lineWidth = 0.15;
    polyline(g, left); g.stroke();
    polyline(g, right); g.stroke();
    g.setLineDash([3, 6]);
    polyline(g, road.centre.map(([x, y]) => [x, y] as [number, number])); g.stroke();
    g.setLineDash([]);
  }

  function drawGrid(g: CanvasRenderingContext2D, pose: Pose, view: number): void {
    g.strokeStyle = '#cfcfcf';
    g.lineWidth = 1 / zoom;
    const step = 10;
    g.beginPath();
    for (let x = Math.floor((pose[1] - view) / step) * step; x < pose[1] + view; x += step) { g.moveTo(x, pose[2] - view); g.lineTo(x, pose[2] + view); }
    for (let y = Math.floor((pose[2] - view) / step) * step; y < pose[2] + view; y += step) { g.moveTo(pose[1] - view, y); g.lineTo(pose[1] + view, y); }
    g.stroke();
  }

  function drawMarks(g: CanvasRenderingContext2D): void {
    g.strokeStyle = 'rgba(20,20,20,0.75)';
    g.lineWidth = 0.22;
    g.lineCap = 'round';
    for (const runs of world.marks) for (const run of runs) {
      if (run.length < 2) continue;
      polyline(g, run);
      g.stroke();
    }
  }

  function drawCarTop(g: CanvasRenderingContext2D, car: Car, pose: Pose): void {
    g.save();
    g.translate(pose[1], pose[2]);
    g.rotate(pose[3]);
    const front = car.cg_to_front_m, rear = front - car.length_m, half = car.width_m / 2;
    for (let i = 0; i < 4; i++) {
      const [wx, wy] = car.wheels[i];
      g.save();
      g.translate(wx, wy);
      if (i < 2) g.rotate(pose[5]);
      g.fillStyle = '#111';
      g.fillRect(-car.wheel_radius_m, -0.11, 2 * car.wheel_radius_m, 0.22);
      g.restore();
    }
    g.fillStyle = 'rgba(192,57,43,0.9)';
    g.strokeStyle = '#5a1a12';
    g.lineWidth = 0.06;
    g.beginPath();
    g.moveTo(front, half * 0.85); g.lineTo(front - 0.3, half); g.lineTo(rear, half); g.lineTo(rear, -half); g.lineTo(front - 0.3, -half); g.lineTo(front, -half * 0.85);
    g.closePath();
    g.fill();
    g.stroke();
    // The windscreen shows which way is ahead.
    g.fillStyle = 'rgba(30,40,60,0.8)';
    g.fillRect(front - 1.9, -half * 0.75, 0.5, half * 1.5);
    g.restore();
  }

  function scaleBar(g: CanvasRenderingContext2D, w: number, hgt: number): void {
    const target = 100 / zoom;
    const mag = Math.pow(10, Math.floor(Math.log10(target)));
    const metres = [1, 2, 5, 10].map((k) => k * mag).filter((m) => m <= target).pop() ?? mag;
    const px = metres * zoom;
    g.strokeStyle = '#222'; g.fillStyle = '#222'; g.lineWidth = 1.5;
    g.beginPath(); g.moveTo(12, hgt - 16); g.lineTo(12, hgt - 10); g.lineTo(12 + px, hgt - 10); g.lineTo(12 + px, hgt - 16); g.stroke();
    g.font = '12px sans-serif';
    g.fillText(`${metres} m`, 18 + px, hgt - 8);
    g.fillText('N ↑', w - 34, 18);
  }

  // ---- chase view: a camera behind and above the car ----
  function drawChase(g: CanvasRenderingContext2D, w: number, hgt: number, d: Description, pose: Pose): void {
    const sky = g.createLinearGradient(0, 0, 0, hgt * 0.45);
    sky.addColorStop(0, '#8fb8e0'); sky.addColorStop(1, '#dbe8f3');
    g.fillStyle = sky; g.fillRect(0, 0, w, hgt);
    const heading = pose[3];
    const c = Math.cos(heading), s = Math.sin(heading);
    const cam = { x: pose[1] - 8 * c, y: pose[2] - 8 * s, z: 3.2 };
    const pitch = 0.16; // looking down a little
    const f = w / (2 * Math.tan(0.5 * 1.1));
    const horizon = hgt * 0.42;
    // World point (x, y, z) to screen; null behind the camera.
    const project = (x: number, y: number, z: number): [number, number] | null => {
      const dx = x - cam.x, dy = y - cam.y, dz = z - cam.z;
      const ahead = dx * c + dy * s;
      const left = -dx * s + dy * c;
      const depth = ahead * Math.cos(pitch) - dz * Math.sin(pitch);
      const up = ahead * Math.sin(pitch) + dz * Math.cos(pitch);
      if (depth < 0.5) return null;
      return [w / 2 - f * left / depth, horizon - f * up / depth + f * Math.tan(pitch)];
    };
    g.fillStyle = d.road ? '#9fbf86' : '#d8d8d8';
    const groundTop = Math.max(0, horizon);
    g.fillRect(0, groundTop, w, hgt - groundTop);
    const quad = (pts: ([number, number] | null)[], colour: string) => {
      if (pts.some((p) => p === null)) return;
      g.fillStyle = colour;
      g.beginPath();
      pts.forEach((p, i) => (i ? g.lineTo(p![0], p![1]) : g.moveTo(p![0], p![1])));
      g.closePath();
      g.fill();
    };
    const range = 400;
    const inFront = (x: number, y: number) => {
      const ahead = (x - cam.x) * c + (y - cam.y) * s;
      return ahead > 0.5 && ahead < range && Math.abs(-(x - cam.x) * s + (y - cam.y) * c) < range;
    };
    if (d.road) {
      const road = d.road, half = road.width_m / 2;
      const edge = (i: number, k: number) => { const [x, y, hd] = road.centre[i]; return project(x - k * half * Math.sin(hd), y + k * half * Math.cos(hd), 0); };
      // Far to near, so that what is nearer paints over.
      const order: number[] = [];
      for (let i = 1; i < road.centre.length; i++) if (inFront(road.centre[i][0], road.centre[i][1]) || inFront(road.centre[i - 1][0], road.centre[i - 1][1])) order.push(i);
      const dist = (i: number) => Math.hypot(road.centre[i][0] - cam.x, road.centre[i][1] - cam.y);
      order.sort((a, b) => dist(b) - dist(a));
      for (const i of order) {
        quad([edge(i - 1, 1), edge(i, 1), edge(i, -1), edge(i - 1, -1)], i % 8 < 4 ? '#8c8c8c' : '#888888');
      }
      for (const patch of road.patches) {
        const pts = patch.outline.filter(([x, y]) => inFront(x, y)).map(([x, y]) => project(x, y, 0.01));
        if (pts.length >= 3) quad(pts, patchColour(patch.mu));
      }
      g.strokeStyle = '#ffffff';
      g.lineWidth = 1.5;
      for (const k of [1, -1]) {
        g.beginPath();
        let open = false;
        for (let i = 0; i < road.centre.length; i++) {
          const [x, y] = road.centre[i];
          const p = inFront(x, y) ? edge(i, k) : null;
          if (!p) { open = false; continue; }
          if (open) g.lineTo(p[0], p[1]); else g.moveTo(p[0], p[1]);
          open = true;
        }
        g.stroke();
      }
      // The centre line's dashes (4 m in every 12 m), so that the road is seen to pass
      // under the car on a straight.
      g.lineWidth = 2;
      g.beginPath();
      for (let i = 1; i < road.centre.length; i++) {
        if (i % 6 >= 2) continue;
        const [ax, ay] = road.centre[i - 1], [bx, by] = road.centre[i];
        if (!inFront(ax, ay) || !inFront(bx, by)) continue;
        const a = project(ax, ay, 0.01), b = project(bx, by, 0.01);
        if (a && b) { g.moveTo(a[0], a[1]); g.lineTo(b[0], b[1]); }
      }
      g.stroke();
    }
    if (!d.road) {
      // Open ground: a 10 m grid, so that the ground is seen to move under the car.
      g.strokeStyle = 'rgba(120,120,120,0.6)';
      g.lineWidth = 1;
      const step = 10, reach = 150;
      const x0 = Math.floor((cam.x - reach) / step) * step, y0 = Math.floor((cam.y - reach) / step) * step;
      const line = (ax: number, ay: number, bx: number, by: number) => {
        // Drawn in 5 m pieces: a piece behind the camera is left out, not projected wrongly.
        const n = Math.ceil(Math.hypot(bx - ax, by - ay) / 5);
        g.beginPath();
        let open = false;
        for (let k = 0; k <= n; k++) {
          const x = ax + ((bx - ax) * k) / n, y = ay + ((by - ay) * k) / n;
          const p = inFront(x, y) ? project(x, y, 0) : null;
          if (!p) { open = false; continue; }
          if (open) g.lineTo(p[0], p[1]); else g.moveTo(p[0], p[1]);
          open = true;
        }
        g.stroke();
      };
      for (let x = x0; x <= cam.x + reach; x += step) line(x, cam.y - reach, x, cam.y + reach);
      for (let y = y0; y <= cam.y + reach; y += step) line(cam.x - reach, y, cam.x + reach, y);
    }
    g.strokeStyle = 'rgba(20,20,20,0.7)';
    g.lineWidth = 2;
    for (const runs of world.marks) for (const run of runs) {
      g.beginPath();
      let open = false;
      for (const [x, y] of run) {
        const p = inFront(x, y) ? project(x, y, 0.02) : null;
        if (!p) { open = false; continue; }
        if (open) g.lineTo(p[0], p[1]); else g.moveTo(p[0], p[1]);
        open = true;
      }
      g.stroke();
    }
    drawCarBox(d.car, pose, project, g);
    g.fillStyle = '#333';
    g.font = '12px sans-serif';
    g.fillText('chase view', 10, 18);
  }

  function drawCarBox(car: Car, pose: Pose, project: (x: number, y: number, z: number) => [number, number] | null, g: CanvasRenderingContext2D): void {
    const c = Math.cos(pose[3]), s = Math.sin(pose[3]);
    const at = (ax: number, ay: number, z: number) => project(pose[1] + ax * c - ay * s, pose[2] + ax * s + ay * c, z);
    const front = car.cg_to_front_m, rear = front - car.length_m, half = car.width_m / 2;
    const face = (pts: ([number, number] | null)[], colour: string) => {
      if (pts.some((p) => !p)) return;
      g.fillStyle = colour;
      g.beginPath();
      pts.forEach((p, i) => (i ? g.lineTo(p![0], p![1]) : g.moveTo(p![0], p![1])));
      g.closePath();
      g.fill();
    };
    // Wheels (dark blocks at the corners), then the body: sides, rear, roof.
    for (let i = 0; i < 4; i++) {
      const [wx, wy] = car.wheels[i];
      const r = car.wheel_radius_m, out = Math.sign(wy) * 0.12;
      face([at(wx - r, wy + out, 0), at(wx + r, wy + out, 0), at(wx + r, wy + out, 2 * r), at(wx - r, wy + out, 2 * r)], '#151515');
    }
    const body = 1.05, roof = 1.4;
    face([at(rear, half, 0.25), at(front, half, 0.25), at(front, half, body), at(rear, half, body)], '#a8322a');
    face([at(rear, -half, 0.25), at(front, -half, 0.25), at(front, -half, body), at(rear, -half, body)], '#a8322a');
    face([at(rear, half, 0.25), at(rear, -half, 0.25), at(rear, -half, body), at(rear, half, body)], '#c0392b');
    face([at(rear + 0.6, half * 0.8, body), at(rear + 0.6, -half * 0.8, body), at(rear + 2.6, -half * 0.8, roof), at(rear + 2.6, half * 0.8, roof)], '#2b3440');
    face([at(rear, half, body), at(rear, -half, body), at(rear + 0.6, -half * 0.8, body), at(rear + 0.6, half * 0.8, body)], '#b0352c');
    // Tail lights.
    face([at(rear - 0.01, half * 0.95, 0.75), at(rear - 0.01, half * 0.55, 0.75), at(rear - 0.01, half * 0.55, 0.9), at(rear - 0.01, half * 0.95, 0.9)], '#ff4a3d');
    face([at(rear - 0.01, -half * 0.55, 0.75), at(rear - 0.01, -half * 0.95, 0.75), at(rear - 0.01, -half * 0.95, 0.9), at(rear - 0.01, -half * 0.55, 0.9)], '#ff4a3d');
  }

  return {
    el,
    destroy() {
      cancelAnimationFrame(raf);
    },
  };
}

function patchColour(mu: number): string {
  if (mu <= 0.3) return 'rgba(190,228,245,0.95)';
  if (mu <= 0.7) return 'rgba(80,110,140,0.85)';
  return 'rgba(120,120,120,0.9)';
}

function polyline(g: CanvasRenderingContext2D, points: [number, number][]): void {
  g.beginPath();
  points.forEach(([x, y], i) => (i ? g.lineTo(x, y) : g.moveTo(x, y)));
}
