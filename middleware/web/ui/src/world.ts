// The world view: the simulator's car on its road, drawn from the stream's `world`
// messages (a channel apart from the bus's signals: the gateway never sees it). Top-down
// (north up, following the car, or the whole road at once), drawn here on a plain 2-D
// canvas; or the driver's view in 3-D (world3d.ts, three.js, loaded when first chosen) from
// a chase camera or the driver's seat. Poses come at 20 Hz and are interpolated to the
// display's frame rate.
import { h, setText } from './util';
import type { Live } from './live';

/** A pose as the channel sends it: [t, x, y, heading, speed, steer, marks]. */
export type Pose = [number, number, number, number, number, number, number];

export interface Patch { name: string; mu: number; outline: [number, number][] }
/** Centreline points: [x, y, heading, height] (height absent in recordings made before it was kept). */
export interface Road { name: string; width_m: number; closed: boolean; length_m: number; centre: [number, number, number, number?][]; patches: Patch[]; verge_mu: number }
export interface Car { length_m: number; width_m: number; cg_to_front_m: number; wheels: [number, number][]; wheel_radius_m: number }
export interface Description { road: Road | null; car: Car }

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

/** Where a point is against the road: its distance from the centreline and the road's
 *  height there. The nearest centreline point is searched from the last one found. */
export class RoadLocator {
  private last = 0;
  constructor(readonly road: Road | null) {}

  private nearest(x: number, y: number): number {
    const c = this.road!.centre;
    const d2 = (i: number) => (c[i][0] - x) ** 2 + (c[i][1] - y) ** 2;
    let best = Math.min(this.last, c.length - 1), bestD = d2(best);
    // Walk downhill from the last station: the car moves little between two calls...
    for (const step of [1, -1]) {
      let i = best;
      for (let n = 0; n < c.length; n++) {
        const j = this.road!.closed ? (i + step + c.length) % c.length : i + step;
        if (j < 0 || j >= c.length || d2(j) >= d2(i)) break;
        i = j;
      }
      if (d2(i) < bestD) { best = i; bestD = d2(i); }
    }
    // ...but a walk that ends far away may have stopped in a dip of the distance (a jump,
    // a road that comes back near itself): a coarse look over the whole road settles it.
    if (bestD > 30 * 30) {
      for (let i = 0; i < c.length; i += 4) if (d2(i) < bestD) { best = i; bestD = d2(i); }
    }
    this.last = best;
    return best;
  }

  /** Distance from the centreline, m, and the road's height there, m. */
  at(x: number, y: number): { off: number; height: number } {
    const road = this.road;
    if (!road || road.centre.length < 2) return { off: Infinity, height: 0 };
    const c = road.centre;
    const i = this.nearest(x, y);
    const j = i + 1 < c.length ? i + 1 : i - 1;
    const [ax, ay] = c[i], [bx, by] = c[j];
    const len2 = (bx - ax) ** 2 + (by - ay) ** 2 || 1;
    const k = Math.max(0, Math.min(1, ((x - ax) * (bx - ax) + (y - ay) * (by - ay)) / len2));
    const height = (c[i][3] ?? 0) + k * ((c[j][3] ?? 0) - (c[i][3] ?? 0));
    return { off: Math.hypot(x - (ax + k * (bx - ax)), y - (ay + k * (by - ay))), height };
  }
}

/** Beyond this distance from the road's edge the car is off the road, m (a wheel on the grass). */
const OFF_ROAD_MARGIN_M = 0.5;

type Mode = 'top' | 'chase' | 'cockpit';

/** The world view's element, drawing the live stream's world while it is in the page. */
export function worldView(live: Live): { el: HTMLElement; destroy(): void } {
  const world = live.world;
  const canvas = h('canvas', { class: 'world-canvas', 'data-testid': 'world-canvas', 'aria-label': 'the car on its road, as the simulator has it' }) as HTMLCanvasElement;
  const canvas3d = h('canvas', { class: 'world-canvas', 'data-testid': 'world-canvas-3d', 'aria-label': 'the driver\'s view of the road, in 3-D', hidden: true }) as HTMLCanvasElement;
  const banner = h('div', { class: 'world-banner', 'data-testid': 'off-road', hidden: true });
  const info = h('div', { class: 'world-info muted small', 'data-testid': 'world-info' });
  const fpsText = h('span', { class: 'muted small', 'data-testid': 'world-fps' });
  const saved = localStorage.getItem('autoplug.world.mode');
  let mode: Mode = saved === 'chase' || saved === 'cockpit' ? saved : 'top';
  // 7 px/m: the 4.35 m car some 30 px long, 100 m of road across the view.
  let zoom = Number(localStorage.getItem('autoplug.world.zoom')) || 7;
  let overview = false;
  const modeButton = (m: Mode, text: string, title: string) =>
    h('button', { class: 'btn', 'data-testid': `world-${m}`, title, onclick: () => { mode = m; overview = false; localStorage.setItem('autoplug.world.mode', m); buttons(); } }, text);
  const top = modeButton('top', 'Top', 'from above, north up, following the car');
  const chase = modeButton('chase', 'Chase 3-D', 'in 3-D, from behind the car');
  const cockpit = modeButton('cockpit', 'Driver 3-D', 'in 3-D, from the driver\'s seat');
  const whole = h('button', { class: 'btn', 'data-testid': 'world-overview', title: 'the whole road, with the car on it', onclick: () => { mode = 'top'; overview = !overview; buttons(); } }, 'Whole road');
  const zoomIn = h('button', { class: 'btn', title: 'zoom in', onclick: () => setZoom(zoom * 1.5) }, '+');
  const zoomOut = h('button', { class: 'btn', title: 'zoom out', onclick: () => setZoom(zoom / 1.5) }, '−');
  function setZoom(z: number): void { overview = false; zoom = Math.max(0.3, Math.min(40, z)); localStorage.setItem('autoplug.world.zoom', String(zoom)); buttons(); }
  let scene: import('./world3d').World3D | null = null;
  let loading3d = false;
  function buttons(): void {
    top.classList.toggle('active', mode === 'top' && !overview);
    whole.classList.toggle('active', mode === 'top' && overview);
    chase.classList.toggle('active', mode === 'chase');
    cockpit.classList.toggle('active', mode === 'cockpit');
    zoomIn.hidden = zoomOut.hidden = mode !== 'top';
    canvas.hidden = mode !== 'top';
    canvas3d.hidden = mode === 'top';
    el.dataset.mode = overview ? 'overview' : mode;
    delete el.dataset.triangles;
    if (mode !== 'top' && !scene && !loading3d) {
      loading3d = true;
      import('./world3d').then(
        (m) => {
          try {
            scene = new m.World3D(canvas3d, world);
          } catch (e: any) {
            problem3d = `3-D needs WebGL, which this browser did not give: ${e.message ?? e}`;
          }
        },
        (e) => { problem3d = `the 3-D view did not load: ${e.message ?? e}`; },
      );
    }
    if (scene) scene.mode = mode === 'cockpit' ? 'cockpit' : 'chase';
  }
  let problem3d: string | null = null;
  const el = h('div', { class: 'card world', 'data-testid': 'world' },
    h('div', { class: 'toolbar' }, h('h3', { text: 'World (the simulator, not the bus)' }), h('div', { class: 'buttons' }, top, whole, chase, cockpit, zoomOut, zoomIn), fpsText),
    h('div', { class: 'world-frame' }, canvas, canvas3d, banner),
    info);
  buttons();

  // Frame rate over the last second, for the page and the tests.
  const frameTimes: number[] = [];
  let raf = 0;
  let lastInfo = 0;
  let locator = new RoadLocator(null);
  let generation = -1;
  const frame = (now: number) => {
    raf = requestAnimationFrame(frame);
    frameTimes.push(now);
    while (frameTimes.length && frameTimes[0] < now - 1000) frameTimes.shift();
    const fps = frameTimes.length;
    draw(now);
    if (now - lastInfo > 250) {
      lastInfo = now;
      // The 3-D view says when it draws coarser than the display to keep its frame rate.
      const coarser = mode !== 'top' && scene?.coarser;
      setText(fpsText, coarser ? `${fps} frames/s at ${scene!.pixelRatio}× resolution` : `${fps} frames/s`);
      el.dataset.fps = String(fps);
    }
  };
  raf = requestAnimationFrame(frame);

  function draw(now: number): void {
    const pose = world.poseAt(now);
    const d = world.description;
    if (generation !== world.generation) {
      generation = world.generation;
      locator = new RoadLocator(d?.road ?? null);
    }
    if (mode !== 'top') {
      if (scene && scene.mode !== mode) scene.mode = mode === 'cockpit' ? 'cockpit' : 'chase';
      const drawn = scene?.draw(now, live.session?.driver ?? null) ?? false;
      if (drawn && scene) {
        el.dataset.triangles = String(scene.triangles);
        el.dataset.pixelRatio = String(scene.pixelRatio);
      }
      if (!drawn) setText(info, problem3d ?? (d ? 'waiting for the car…' : scene ? 'no world: this bus is not the virtual car’s' : 'loading the 3-D view…'));
    } else {
      drawTopCanvas(pose, d);
    }
    if (!d || !pose) {
      banner.hidden = true;
      return;
    }
    // What the tests compare with the simulator's own numbers.
    el.dataset.t = pose[0].toFixed(3);
    el.dataset.x = pose[1].toFixed(2);
    el.dataset.y = pose[2].toFixed(2);
    el.dataset.heading = (pose[3] * 180 / Math.PI).toFixed(2);
    el.dataset.marks = String(world.marks.reduce((n, runs) => n + runs.reduce((m, r) => m + r.length, 0), 0));
    // Off the road: said on the view, with the way back (the car is easily lost at speed
    // on the grass, a dot when zoomed out).
    const where = d.road ? locator.at(pose[1], pose[2]) : null;
    const offBy = where ? where.off - d.road!.width_m / 2 : 0;
    const off = where !== null && offBy > OFF_ROAD_MARGIN_M;
    banner.hidden = !off;
    el.dataset.offRoad = String(off);
    if (off) {
      setText(banner, `Off the road: ${offBy < 100 ? offBy.toFixed(0) : (Math.round(offBy / 10) * 10).toFixed(0)} m from its edge, on grass (µ ${d.road!.verge_mu}). ${mode === 'top' && !overview ? 'Whole road shows where.' : ''} Stop, then Back to the start.`);
    }
    const road = d.road ? `${d.road.name}` : 'open ground';
    // The speed is the car's forward speed (negative when it moves backwards).
    const speed = pose[4] * 3.6;
    const mu = live.session?.driver;
    const friction = mu && (mu.mu_left !== 1 || mu.mu_right !== 1) ? ` · road µ ${mu.mu_left} left, ${mu.mu_right} right` : '';
    if (mode === 'top' || scene) setText(info, `${road} · ${Math.abs(speed) < 0.5 ? '0' : speed.toFixed(0)} km/h${speed < -0.5 ? ' (backwards)' : ''} · heading ${(((pose[3] * 180 / Math.PI) % 360 + 360) % 360).toFixed(0)}° · t ${pose[0].toFixed(1)} s${friction}`);
  }

  function drawTopCanvas(pose: Pose | null, d: Description | null): void {
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
    if (!d || !pose) {
      g.fillStyle = '#d9dfd2';
      g.fillRect(0, 0, w, hgt);
      g.fillStyle = '#555';
      g.font = '14px sans-serif';
      g.fillText(d ? 'waiting for the car…' : 'no world: this bus is not the virtual car’s', 16, 28);
      setText(info, '');
      return;
    }
    drawTop(g, w, hgt, d, pose);
  }

  // ---- top-down, north up: the car in the middle, or the whole road ----
  function drawTop(g: CanvasRenderingContext2D, w: number, hgt: number, d: Description, pose: Pose): void {
    g.fillStyle = d.road ? '#b8cf9c' : '#e4e4e4';
    g.fillRect(0, 0, w, hgt);
    let scale = zoom, cx = pose[1], cy = pose[2];
    if (overview) {
      // The road and the car, whole, with a margin.
      const xs = [pose[1], ...(d.road?.centre.map((p) => p[0]) ?? [])], ys = [pose[2], ...(d.road?.centre.map((p) => p[1]) ?? [])];
      const x0 = Math.min(...xs) - 20, x1 = Math.max(...xs) + 20, y0 = Math.min(...ys) - 20, y1 = Math.max(...ys) + 20;
      scale = Math.min(w / (x1 - x0), hgt / (y1 - y0));
      cx = (x0 + x1) / 2;
      cy = (y0 + y1) / 2;
    }
    g.save();
    g.translate(w / 2, hgt / 2);
    g.scale(scale, -scale);
    g.translate(-cx, -cy);
    const view = Math.hypot(w, hgt) / scale / 2 + 10;
    const near = (x: number, y: number) => Math.abs(x - cx) < view && Math.abs(y - cy) < view;
    if (d.road) drawRoadTop(g, d.road, near, scale);
    else drawGrid(g, pose, view, scale);
    drawMarks(g);
    g.strokeStyle = 'rgba(31,95,191,0.8)';
    g.lineWidth = 1.5 / scale;
    polyline(g, world.path);
    g.stroke();
    drawCarTop(g, d.car, pose);
    // Zoomed out the car is smaller than a pixel: a marker of fixed size shows it.
    if (scale < 3) drawCarMarker(g, pose, scale);
    g.restore();
    scaleBar(g, w, hgt, scale);
  }

  function drawRoadTop(g: CanvasRenderingContext2D, road: Road, near: (x: number, y: number) => boolean, scale: number): void {
    const half = road.width_m / 2;
    const side = (k: number) => road.centre.map(([x, y, hd]) => [x - k * half * Math.sin(hd), y + k * half * Math.cos(hd)] as [number, number]);
    const left = side(1), right = side(-1), mid = side(0);
    // The friction the person set (Dry, Wet, Split) tints each half of the asphalt.
    const driver = live.session?.driver;
    const halves: [[number, number][], [number, number][], number][] = [[left, mid, driver?.mu_left ?? 1], [mid, right, driver?.mu_right ?? 1]];
    for (const [a, b, mu] of halves) {
      g.fillStyle = mu >= 0.9 ? '#8f8f8f' : patchColour(mu);
      // Quads between consecutive centre points, only those near the view.
      g.beginPath();
      for (let i = 1; i < road.centre.length; i++) {
        if (!near(road.centre[i][0], road.centre[i][1])) continue;
        g.moveTo(a[i - 1][0], a[i - 1][1]);
        g.lineTo(a[i][0], a[i][1]);
        g.lineTo(b[i][0], b[i][1]);
        g.lineTo(b[i - 1][0], b[i - 1][1]);
        g.closePath();
      }
      g.fill();
    }
    for (const patch of road.patches) {
      g.fillStyle = patchColour(patch.mu);
      polyline(g, patch.outline);
      g.closePath();
      g.fill();
    }
    if (scale < 1.5) return;
    g.strokeStyle = '#fff';
    g.lineWidth = 0.15;
    polyline(g, left); g.stroke();
    polyline(g, right); g.stroke();
    g.setLineDash([3, 6]);
    polyline(g, road.centre.map(([x, y]) => [x, y] as [number, number])); g.stroke();
    g.setLineDash([]);
  }

  function drawGrid(g: CanvasRenderingContext2D, pose: Pose, view: number, scale: number): void {
    g.strokeStyle = '#cfcfcf';
    g.lineWidth = 1 / scale;
    const step = scale < 1 ? 100 : 10;
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

  function drawCarMarker(g: CanvasRenderingContext2D, pose: Pose, scale: number): void {
    g.save();
    g.translate(pose[1], pose[2]);
    g.rotate(pose[3]);
    g.scale(1 / scale, 1 / scale);
    g.fillStyle = '#c0392b';
    g.strokeStyle = '#fff';
    g.lineWidth = 2;
    g.beginPath();
    g.moveTo(12, 0); g.lineTo(-8, 8); g.lineTo(-4, 0); g.lineTo(-8, -8);
    g.closePath();
    g.fill();
    g.stroke();
    g.restore();
  }

  function scaleBar(g: CanvasRenderingContext2D, w: number, hgt: number, scale: number): void {
    const target = 100 / scale;
    const mag = Math.pow(10, Math.floor(Math.log10(target)));
    const metres = [1, 2, 5, 10].map((k) => k * mag).filter((m) => m <= target).pop() ?? mag;
    const px = metres * scale;
    g.strokeStyle = '#222'; g.fillStyle = '#222'; g.lineWidth = 1.5;
    g.beginPath(); g.moveTo(12, hgt - 16); g.lineTo(12, hgt - 10); g.lineTo(12 + px, hgt - 10); g.lineTo(12 + px, hgt - 16); g.stroke();
    g.font = '12px sans-serif';
    g.fillText(`${metres} m`, 18 + px, hgt - 8);
    g.fillText('N ↑', w - 34, 18);
  }

  return {
    el,
    destroy() {
      cancelAnimationFrame(raf);
      scene?.dispose();
    },
  };
}

export function patchColour(mu: number): string {
  if (mu <= 0.3) return 'rgba(190,228,245,0.95)';
  if (mu <= 0.7) return 'rgba(80,110,140,0.85)';
  return 'rgba(120,120,120,0.9)';
}

function polyline(g: CanvasRenderingContext2D, points: [number, number][]): void {
  g.beginPath();
  points.forEach(([x, y], i) => (i ? g.lineTo(x, y) : g.moveTo(x, y)));
}
