// The driver's view in 3-D (three.js, WebGL): the simulator's road with its width, edge and
// centre markings, friction patches and height (its grades), the grass beside it, the car
// with its steered front wheels, its tyre marks; seen from a chase camera behind the car or
// from the driver's seat. Loaded only when the view is chosen (three.js is most of its
// size), drawn at the display's frame rate from the same interpolated poses as the top view.
//
// World axes are the simulator's: x east, y north, heights up. three.js is y-up, so a point
// (x, y, height) is drawn at (x, height, -y).
import * as THREE from 'three';
import type { Car, Description, Pose, World } from './world';
import { patchColour, RoadLocator } from './world';

export type Camera3D = 'chase' | 'cockpit';

/** Grass beside the road, each side, m: it slopes from the road's height to the plain's. */
const VERGE_M = 40;
/** How far one sees, m (fog from a third of it). */
const VIEW_M = 600;
/** The sharpest the view is drawn, device pixels per CSS pixel: beyond it a phone's GPU spends
 *  its time on pixels one cannot tell apart. */
const MAX_PIXEL_RATIO = 1.5;
/** The coarsest: the view stays legible at three device pixels for four CSS pixels. */
const MIN_PIXEL_RATIO = 0.75;
/** A frame later than this (median of a window) misses a 60 Hz display's every other refresh. */
const SLOW_FRAME_MS = 20;
/** Frames in the window that decides whether the view is drawn coarser. */
const FRAME_WINDOW = 30;

const v3 = (x: number, y: number, z: number) => new THREE.Vector3(x, z, -y);

/** The ground's height at (x, y): the road's on it, sloping to the plain's over the verge. */
function groundHeight(locator: RoadLocator, x: number, y: number): number {
  const road = locator.road;
  if (!road) return 0;
  const { off, height } = locator.at(x, y);
  const half = road.width_m / 2;
  if (off <= half) return height;
  return height * Math.max(0, 1 - (off - half) / VERGE_M);
}

/** The asphalt's colour under the friction the person set (Dry, Wet, Split). */
function asphalt(mu: number): THREE.Color {
  if (mu >= 0.9) return new THREE.Color('#6e7176');
  return new THREE.Color(patchColour(mu).replace(/rgba\((\d+),(\d+),(\d+),[^)]*\)/, 'rgb($1,$2,$3)'));
}

export class World3D {
  private renderer: THREE.WebGLRenderer;
  private scene = new THREE.Scene();
  private camera = new THREE.PerspectiveCamera(60, 1, 0.1, VIEW_M * 1.5);
  private roadGroup = new THREE.Group();
  private car = new THREE.Group();
  private frontWheels: THREE.Object3D[] = [];
  private marks: THREE.LineSegments;
  private marksSeen = -1;
  private plain: THREE.Mesh;
  private generation = -1;
  private locator = new RoadLocator(null);
  private halves: THREE.Mesh[] = [];
  private friction = '';
  private chaseHeading: number | null = null;
  // Dynamic resolution (as games hold their frame rate): a window of frame intervals whose
  // median is slow lowers the pixel ratio a step; it never rises again in this view, so it
  // cannot swing between a sharp slow picture and a coarse fluid one.
  private frameIntervals: number[] = [];
  private lastFrame = 0;
  mode: Camera3D = 'chase';

  constructor(private canvas: HTMLCanvasElement, private world: World) {
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: false, powerPreference: 'high-performance' });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, MAX_PIXEL_RATIO));
    const sky = new THREE.Color('#a9c8e6');
    this.scene.background = sky;
    this.scene.fog = new THREE.Fog(sky, VIEW_M / 3, VIEW_M);
    this.scene.add(new THREE.HemisphereLight('#ffffff', '#5d6b4a', 2.2));
    const sun = new THREE.DirectionalLight('#ffffff', 1.6);
    sun.position.set(-0.4, 1, 0.3);
    this.scene.add(sun);
    this.plain = new THREE.Mesh(new THREE.PlaneGeometry(4 * VIEW_M, 4 * VIEW_M), new THREE.MeshLambertMaterial({ color: '#8fae72' }));
    this.plain.rotation.x = -Math.PI / 2;
    this.plain.position.y = -0.05;
    this.scene.add(this.plain, this.roadGroup, this.car);
    this.marks = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: '#1d1d1d', transparent: true, opacity: 0.8 }));
    this.scene.add(this.marks);
  }

  private ground(x: number, y: number): number {
    return groundHeight(this.locator, x, y);
  }

  /** Draws the scene at wall time `now` (ms), the road's halves with the friction the person
   *  set; false when there is nothing to draw yet. */
  draw(now: number, driver: { mu_left: number; mu_right: number } | null): boolean {
    const d = this.world.description;
    const pose = this.world.poseAt(now);
    if (!d || !pose) return false;
    if (this.generation !== this.world.generation) {
      this.generation = this.world.generation;
      this.build(d);
    }
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    if (w === 0 || h === 0) return false;
    this.adaptResolution(now);
    const ratio = this.renderer.getPixelRatio();
    if (this.canvas.width !== Math.floor(w * ratio) || this.canvas.height !== Math.floor(h * ratio)) {
      this.renderer.setSize(w, h, false);
      this.camera.aspect = w / h;
      this.camera.updateProjectionMatrix();
    }
    const friction = `${driver?.mu_left ?? 1}/${driver?.mu_right ?? 1}`;
    if (friction !== this.friction && this.halves.length === 2) {
      this.friction = friction;
      (this.halves[0].material as THREE.MeshLambertMaterial).color = asphalt(driver?.mu_left ?? 1);
      (this.halves[1].material as THREE.MeshLambertMaterial).color = asphalt(driver?.mu_right ?? 1);
    }
    this.placeCar(d.car, pose);
    this.updateMarks();
    this.placeCamera(pose);
    // The plain follows the car (it is endless); the road and marks stay where they are.
    this.plain.position.x = pose[1];
    this.plain.position.z = -pose[2];
    this.renderer.render(this.scene, this.camera);
    return true;
  }

  /** Lowers the pixel ratio a step when the last window of frames came too slowly. A gap
   *  (the tab hidden, the top view shown) starts a new window rather than counting as slow. */
  private adaptResolution(now: number): void {
    const interval = now - this.lastFrame;
    this.lastFrame = now;
    if (interval > 250) {
      this.frameIntervals.length = 0;
      return;
    }
    this.frameIntervals.push(interval);
    if (this.frameIntervals.length < FRAME_WINDOW) return;
    const median = [...this.frameIntervals].sort((a, b) => a - b)[FRAME_WINDOW >> 1];
    this.frameIntervals.length = 0;
    const ratio = this.renderer.getPixelRatio();
    if (median > SLOW_FRAME_MS && ratio > MIN_PIXEL_RATIO) {
      this.renderer.setPixelRatio(Math.max(MIN_PIXEL_RATIO, ratio - 0.25));
    }
  }

  /** Device pixels drawn per CSS pixel (lower than the display's when frames came slowly). */
  get pixelRatio(): number {
    return this.renderer.getPixelRatio();
  }

  /** Whether the view is drawn coarser than it would be for its frame rate's sake. */
  get coarser(): boolean {
    return this.pixelRatio < Math.min(window.devicePixelRatio || 1, MAX_PIXEL_RATIO);
  }

  /** Triangles in the last frame drawn (the page shows it to its tests). */
  get triangles(): number {
    return this.renderer.info.render.triangles;
  }

  dispose(): void {
    this.scene.traverse((o) => {
      const mesh = o as THREE.Mesh;
      mesh.geometry?.dispose();
      const m = mesh.material as THREE.Material | THREE.Material[] | undefined;
      if (Array.isArray(m)) m.forEach((x) => x.dispose());
      else m?.dispose();
    });
    this.renderer.dispose();
  }

  private build(d: Description): void {
    for (const child of [...this.roadGroup.children]) {
      this.roadGroup.remove(child);
      (child as THREE.Mesh).geometry?.dispose();
    }
    this.locator = new RoadLocator(d.road);
    this.halves = [];
    this.friction = '';
    this.buildCar(d.car);
    this.marksSeen = -1;
    const road = d.road;
    if (!road || road.centre.length < 2) {
      // Open ground: a 10 m grid, so the ground is seen to move under the car.
      const grid = new THREE.GridHelper(2000, 200, '#6f8a58', '#7f9a68');
      grid.position.y = 0.01;
      this.roadGroup.add(grid);
      return;
    }
    const c = road.centre;
    const half = road.width_m / 2;
    const side = (i: number, k: number, lift = 0) => {
      const [x, y, hd, z] = c[i];
      return v3(x - k * Math.sin(hd), y + k * Math.cos(hd), (z ?? 0) + lift);
    };
    // A ribbon between two offsets from the centreline (k1 left of k2), over stations
    // `from`..`to`, with heights from `lift`: the road, its verges and its markings.
    const ribbon = (k1: number, k2: number, colour: string, lift: (i: number, k: number) => number, keep: (i: number) => boolean = () => true) => {
      const positions: number[] = [];
      for (let i = 1; i < c.length; i++) {
        if (!keep(i)) continue;
        const a1 = side(i - 1, k1, lift(i - 1, k1)), a2 = side(i - 1, k2, lift(i - 1, k2));
        const b1 = side(i, k1, lift(i, k1)), b2 = side(i, k2, lift(i, k2));
        positions.push(a1.x, a1.y, a1.z, a2.x, a2.y, a2.z, b1.x, b1.y, b1.z);
        positions.push(b1.x, b1.y, b1.z, a2.x, a2.y, a2.z, b2.x, b2.y, b2.z);
      }
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.Float32BufferAttribute(positions, 3));
      g.computeVertexNormals();
      const mesh = new THREE.Mesh(g, new THREE.MeshLambertMaterial({ color: colour, side: THREE.DoubleSide }));
      this.roadGroup.add(mesh);
      return mesh;
    };
    const flat = (lift: number) => () => lift;
    // Grass that slopes from the road's edge down to the plain over the verge.
    const verge = (i: number, k: number) => (Math.abs(k) > half + 0.01 ? -(c[i][3] ?? 0) - 0.04 : -0.02);
    ribbon(half + VERGE_M, half, '#93b276', verge);
    ribbon(-half, -half - VERGE_M, '#93b276', verge);
    this.halves = [ribbon(half, 0, '#6e7176', flat(0)), ribbon(0, -half, '#6e7176', flat(0))];
    // Edge lines (15 cm) and the centre line's dashes (4 m in every 12 m).
    ribbon(half - 0.2, half - 0.35, '#f4f4f4', flat(0.015));
    ribbon(-half + 0.35, -half + 0.2, '#f4f4f4', flat(0.015));
    ribbon(0.075, -0.075, '#f4f4f4', flat(0.015), (i) => i % 6 < 2);
    for (const patch of road.patches) this.buildPatch(patch.outline, patch.mu);
  }

  private buildPatch(outline: [number, number][], mu: number): void {
    // The outline is one side's stations, then the other side's back: a strip between.
    const n = Math.floor(outline.length / 2);
    if (n < 2) return;
    const positions: number[] = [];
    const at = (p: [number, number]) => v3(p[0], p[1], this.locator.at(p[0], p[1]).height + 0.02);
    for (let i = 1; i < n; i++) {
      const a1 = at(outline[i - 1]), b1 = at(outline[i]);
      const a2 = at(outline[outline.length - i]), b2 = at(outline[outline.length - 1 - i]);
      positions.push(a1.x, a1.y, a1.z, a2.x, a2.y, a2.z, b1.x, b1.y, b1.z);
      positions.push(b1.x, b1.y, b1.z, a2.x, a2.y, a2.z, b2.x, b2.y, b2.z);
    }
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(positions, 3));
    g.computeVertexNormals();
    const colour = asphalt(Math.min(mu, 0.89));
    this.roadGroup.add(new THREE.Mesh(g, new THREE.MeshLambertMaterial({ color: colour, side: THREE.DoubleSide, transparent: true, opacity: 0.85 })));
  }

  private buildCar(car: Car): void {
    for (const child of [...this.car.children]) this.car.remove(child);
    this.frontWheels = [];
    // Built in the car's own axes (x forward, y left, z up) under a group that is turned
    // into three.js's axes, so the car's dimensions read as the simulator gives them.
    const body = new THREE.Group();
    body.rotation.x = -Math.PI / 2;
    this.car.add(body);
    const front = car.cg_to_front_m, rear = front - car.length_m, width = car.width_m;
    const box = (length: number, w: number, h: number, x: number, z: number, colour: string) => {
      const mesh = new THREE.Mesh(new THREE.BoxGeometry(length, w, h), new THREE.MeshLambertMaterial({ color: colour }));
      mesh.position.set(x, 0, z);
      body.add(mesh);
      return mesh;
    };
    // Body to the waist (0.25-0.85 m), then the glasshouse; the driver's eyes (1.2 m) are
    // inside it, so from the seat one sees the bonnet and the road.
    box(car.length_m, width, 0.6, (front + rear) / 2, 0.25 + 0.3, '#c0392b');
    box(car.length_m * 0.55, width * 0.88, 0.55, rear + car.length_m * 0.42, 0.85 + 0.275, '#2b3440');
    // Tail lights and headlamps, so which end is which shows from any side.
    for (const y of [width * 0.36, -width * 0.36]) {
      const tail = box(0.04, 0.3, 0.12, rear - 0.02, 0.85, '#ff3b30');
      tail.position.y = y;
      const head = box(0.04, 0.3, 0.12, front + 0.02, 0.8, '#fff6d0');
      head.position.y = y;
    }
    const r = car.wheel_radius_m;
    car.wheels.forEach(([wx, wy], i) => {
      const holder = new THREE.Group();
      holder.position.set(wx, wy, r);
      const tyre = new THREE.Mesh(new THREE.CylinderGeometry(r, r, 0.22, 14), new THREE.MeshLambertMaterial({ color: '#151515' }));
      // The cylinder's axis (y) is the car's lateral axis already.
      holder.add(tyre);
      body.add(holder);
      if (i < 2) this.frontWheels.push(holder);
    });
  }

  private placeCar(car: Car, pose: Pose): void {
    const [, x, y, heading, , steer] = pose;
    const z = this.ground(x, y);
    // Pitch from the ground's heights under the axles.
    const c = Math.cos(heading), s = Math.sin(heading);
    const ahead = this.ground(x + 1.3 * c, y + 1.3 * s), behind = this.ground(x - 1.3 * c, y - 1.3 * s);
    void car;
    const pitch = Math.atan2(ahead - behind, 2.6);
    this.car.position.copy(v3(x, y, z));
    this.car.rotation.set(0, 0, 0);
    this.car.rotateY(heading);
    // Nose up on a climb: about the car's lateral axis (three.js z before the turn).
    this.car.rotateZ(pitch);
    for (const wheel of this.frontWheels) wheel.rotation.z = steer;
    this.car.userData.pitch = pitch;
  }

  private updateMarks(): void {
    const count = this.world.marks.reduce((n, runs) => n + runs.reduce((m, r) => m + r.length, 0), 0);
    if (count === this.marksSeen) return;
    this.marksSeen = count;
    const positions: number[] = [];
    for (const runs of this.world.marks) for (const run of runs) {
      for (let i = 1; i < run.length; i++) {
        const [ax, ay] = run[i - 1], [bx, by] = run[i];
        positions.push(ax, this.ground(ax, ay) + 0.03, -ay, bx, this.ground(bx, by) + 0.03, -by);
      }
    }
    this.marks.geometry.dispose();
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(positions, 3));
    this.marks.geometry = g;
  }

  private placeCamera(pose: Pose): void {
    const [, x, y, heading] = pose;
    const z = this.ground(x, y);
    if (this.mode === 'cockpit') {
      // The driver's eyes: left of the centre line, a little ahead of the centre of
      // gravity, 1.15 m up; looking along the car, pitched with it.
      const c = Math.cos(heading), s = Math.sin(heading);
      const pitch = this.car.userData.pitch ?? 0;
      const eye = v3(x + 0.1 * c - 0.37 * s, y + 0.1 * s + 0.37 * c, z + 1.2);
      this.camera.position.copy(eye);
      this.camera.up.set(0, 1, 0);
      const look = v3(x + 50 * c - 0.37 * s, y + 50 * s + 0.37 * c, z + 1.2 + 50 * Math.tan(pitch) - 1.2);
      this.camera.lookAt(look);
      this.camera.fov = 65;
      this.chaseHeading = null;
    } else {
      // Behind and above, swinging round after the car rather than fixed to it (a spin
      // is seen as a spin).
      const target = this.chaseHeading === null ? heading : this.chaseHeading + wrap(heading - this.chaseHeading) * 0.12;
      this.chaseHeading = target;
      const c = Math.cos(target), s = Math.sin(target);
      const back = 7.5;
      const camZ = Math.max(this.ground(x - back * c, y - back * s), z) + 2.6;
      this.camera.position.copy(v3(x - back * c, y - back * s, camZ));
      this.camera.lookAt(v3(x + 4 * c, y + 4 * s, z + 0.9));
      this.camera.fov = 60;
    }
    this.camera.updateProjectionMatrix();
  }
}

function wrap(a: number): number {
  return Math.atan2(Math.sin(a), Math.cos(a));
}
