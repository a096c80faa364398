// The dashboard in a real Chromium (Debian's, driven headless by playwright-core) against a
// running `autoplug dashboard` on the virtual car: every view renders without a console
// error, the Car view follows the bus, the report's two scenarios are done from the page
// (flash the faulty software, see the symptom, see the verdict, flash the fix, see it
// pass), driving from the page moves the car (and the world view shows it on its road,
// the faulty ABS's spin with its tyre marks), the phone layout fits, and screenshots of
// every view at desktop and phone size are written for a person to look at.
//
// node tests/dashboard.mjs BASE_URL TOKEN SCREENSHOT_DIR [--firmware]
//
// --firmware: the report's two scenarios alone, on a dashboard whose nine ECUs run their
// firmware on emulated MCUs, its library holding the real signed releases it built itself
// (scripts/dashboard-test --firmware); its screenshots are named firmware-*.png.

import assert from 'node:assert/strict';
import { mkdirSync, readFileSync } from 'node:fs';
import { McapIndexedReader, TempBuffer } from '@mcap/core';
import { launchChromium, steps, until } from './harness.mjs';

const [base, token, shots, mode] = process.argv.slice(2);
if (!base || !token || !shots || (mode !== undefined && mode !== '--firmware')) {
  console.error('usage: node tests/dashboard.mjs BASE_URL TOKEN SCREENSHOT_DIR [--firmware]');
  process.exit(2);
}
const onFirmware = mode === '--firmware';
const shotPrefix = onFirmware ? 'firmware-' : 'desktop-';
mkdirSync(shots, { recursive: true });

const VIEWS = {
  car: '[data-testid=speed]',
  plots: '.uplot',
  bus: '[data-testid=msg-VehicleSpeedMsg]',
  diagnostics: '[data-testid=verdict-cruise]',
  ecus: '[data-testid=inventory-cruise]',
  trips: '[data-testid=trip-current]',
  recordings: '[data-testid=record]',
  drive: '[data-testid=drive-speed]',
};

const browser = await launchChromium();
const { ok, watch, problems, run, count } = steps(browser);

async function state() {
  const response = await fetch(`${base}/api/state`);
  return response.json();
}

async function view(page, name) {
  await page.click(`nav a[data-view=${name}]`);
  await page.waitForSelector(VIEWS[name], { timeout: 10_000 });
}

/** The simulator's latest pose, from the world channel (`GET /api/world`). */
async function simPose() {
  const world = await (await fetch(`${base}/api/world`)).json();
  const p = world.poses[world.poses.length - 1];
  return p ? { t: p[0], x: p[1], y: p[2], heading: (p[3] * 180) / Math.PI, speed: p[4] } : null;
}

/** The simulator's pose at time `t` (s), interpolated between the world channel's poses
 *  (20 a second), or null when `t` is outside what the channel holds. */
async function simPoseAt(t) {
  const poses = (await (await fetch(`${base}/api/world`)).json()).poses;
  for (let i = 1; i < poses.length; i++) {
    const [p, q] = [poses[i - 1], poses[i]];
    if (p[0] <= t && t <= q[0]) {
      const f = q[0] > p[0] ? (t - p[0]) / (q[0] - p[0]) : 0;
      return { x: p[1] + f * (q[1] - p[1]), y: p[2] + f * (q[2] - p[2]) };
    }
  }
  return null;
}

/** What the world view draws now: the car's position and heading, the tyre-mark points
 *  it holds, its frame rate over the last second. */
async function pagePose(page) {
  const world = await page.waitForSelector('[data-testid=world][data-x]', { timeout: 10_000 });
  const n = async (name) => Number(await world.getAttribute(`data-${name}`));
  return { t: await n('t'), x: await n('x'), y: await n('y'), heading: await n('heading'), marks: await n('marks'), fps: await n('fps') };
}

/** The dashboard car's road, from the world channel's description: its centreline
 *  (a point every 2 m) and width. */
async function worldRoad(from = base) {
  const world = await (await fetch(`${from}/api/world`)).json();
  return world.description?.road ?? null;
}

/** Where a pose lies on `road`: the station of the nearest centreline point, m, and how
 *  far from the centreline, m. */
function onRoad(road, p) {
  let best = { station: 0, off: Infinity };
  road.centre.forEach(([x, y], i) => {
    const off = Math.hypot(p.x - x, p.y - y);
    if (off < best.off) best = { station: 2 * i, off };
  });
  return best;
}

/** Where the car stood when the test began (its start), from the simulator. */
let startPose = null;

/** Takes the standing car back to where it started, from the Drive view. */
async function toStart(page) {
  await view(page, 'drive');
  await page.click('[data-testid=road-start]');
  await until('the car back at its start', async () => {
    const p = await simPose();
    return p && Math.hypot(p.x - startPose.x, p.y - startPose.y) < 0.5 && Math.abs(p.heading - startPose.heading) < 0.5;
  }, 5_000);
}

async function shownSpeed(page) {
  return Number(await page.getAttribute('[data-testid=speed]', 'data-value'));
}

async function speedNow() {
  return (await state()).signals['Vehicle.Speed'] ?? 0;
}

/** Holds the accelerator (keyboard, Drive view) until the bus shows `kmh`. */
async function accelerateTo(page, kmh) {
  await page.keyboard.up('ArrowDown');
  await page.keyboard.down('ArrowUp');
  await until(`${kmh} km/h`, async () => (await speedNow()) >= kmh, 60_000);
  await page.keyboard.up('ArrowUp');
  // The pedal springs back (the page ramps it down): a pedal still pressed would cancel
  // a cruise switched on now.
  await page.waitForTimeout(700);
}

/** Brakes to a stop and keeps the brake pressed (in gear at idle, the car creeps): the
 *  ECUs take a programming session only once the bus has shown standstill for 0.5 s. */
async function brakeToStop(page) {
  await page.keyboard.down('ArrowDown');
  await until('the car to stop', async () => (await speedNow()) < 0.5, 60_000);
  await page.waitForTimeout(1000);
}

async function verdict(page, ecu) {
  const cell = page.locator(`[data-testid=verdict-${ecu}] td`).nth(1);
  return cell.getAttribute('data-verdict');
}

async function flash(page, ecu, image) {
  await view(page, 'ecus');
  await page.selectOption('[data-testid=flash-image]', image);
  await page.selectOption('[data-testid=flash-ecu]', ecu);
  // F1A0 in the inventory: the slot the ECU runs now (the image goes to the other one).
  const before = await until(`the inventory to show the slot ${ecu} runs`, async () => {
    const shown = await page.textContent(`[data-testid=slot-${ecu}]`);
    return /^slot [AB], /.test(shown ?? '') ? shown : null;
  }, 15_000);
  await page.click('[data-testid=flash-start]');
  // The bar moves while the image goes over the bus.
  const midway = await until('the progress bar to move', async () => {
    if ((await page.getAttribute('[data-testid=flash-status]', 'data-state')) === 'failed') {
      throw new Error(await page.textContent('[data-testid=flash-status]'));
    }
    const v = Number(await page.getAttribute('[data-testid=flash-progress]', 'value'));
    return v > 0 && v < 100 && (await page.isVisible('[data-testid=flash-progress]')) ? v : null;
  }, 60_000);
  await until(`${image} flashed`, async () => {
    const s = await page.getAttribute('[data-testid=flash-status]', 'data-state');
    if (s === 'failed') throw new Error(await page.textContent('[data-testid=flash-status]'));
    return s === 'done';
  }, 120_000);
  // The status names the slot written and the bytes that went over CAN: one image of
  // the release, not the whole file.
  const done = await page.textContent('[data-testid=flash-status]');
  const into = /into slot ([AB])/.exec(done)?.[1];
  assert.ok(into && !before.startsWith(`slot ${into}`), `ran ${before}, status: ${done}`);
  const library = await page.textContent(`[data-testid=flash-image] option[value="${image}"]`);
  const fileSize = /\(([^()]+)\)$/.exec(library)?.[1];
  assert.ok(fileSize && !done.includes(fileSize), `status ${done} shows the file's size ${fileSize}`);
  const running = await until(`the inventory to show ${ecu} on slot ${into}`, async () => {
    const shown = await page.textContent(`[data-testid=slot-${ecu}]`);
    return shown?.startsWith(`slot ${into}, `) ? shown : null;
  }, 15_000);
  const version = /-(\d+\.\d+\.\d+)/.exec(image)[1];
  const inventory = await until(`the inventory to show ${ecu} ${version}`, async () => {
    const shown = await page.textContent(`[data-testid=inventory-${ecu}] .sw`);
    return shown === version ? shown : null;
  }, 15_000);
  ok(`flashed ${image} into ${ecu} from the ECUs view (bar seen at ${midway.toFixed(0)} %), inventory shows ${inventory}, ${before} → ${running}`);
}

/** The simulator steers along the road (the Drive view's switch), so that a person on
 *  the pedals stays on the circuit at the demonstrations' speeds. */
async function steerAlongRoad(page) {
  await view(page, 'drive');
  if ((await page.getAttribute('[data-testid=steer-along-road]', 'data-on')) !== 'true') {
    await page.click('[data-testid=steer-along-road]');
  }
  await until('the simulator steering', async () => (await state()).session?.driver?.steers_along_road === true, 5_000);
  // The page learns it from the session's state, which comes twice a second.
  await until('the page to show the simulator steering', async () => (await page.getAttribute('[data-testid=steer-along-road]', 'data-on')) === 'true', 5_000);
}

/** Where the car is on the road, from the simulator. */
async function station() {
  return onRoad(await worldRoad(), await simPose()).station;
}

/** Report scenario 1 from the page: flash the faulty cruise, see it oscillate and the
 *  verdict, flash the fix, see the verdict clear. The car stands when it starts. */
async function scenario1(desktop) {
  // Report scenario 1: the cruise control.
  await flash(desktop, 'cruise', 'cruise-1.1.0-faulty.img');
  // What a person sees after a flash: the slot written, the bytes sent, the new slot.
  await desktop.screenshot({ path: `${shots}/${shotPrefix}ecus-flashed.png` });
  await view(desktop, 'drive');
  await until('the wheel', async () => (await desktop.getAttribute('[data-testid=drive-auth]', 'data-ok')) === 'true', 10_000);
  await toStart(desktop);
  await steerAlongRoad(desktop);
  await accelerateTo(desktop, 90);
  await desktop.keyboard.press('c');
  await until('cruise on', async () => (await state()).signals['Vehicle.ADAS.CruiseControl.IsActive'] === 1, 5_000);
  const speeds = [];
  const watchUntil = Date.now() + 20_000;
  while (Date.now() < watchUntil) {
    speeds.push((await state()).signals['Vehicle.Speed']);
    await new Promise((r) => setTimeout(r, 200));
  }
  await view(desktop, 'car');
  await desktop.waitForTimeout(500);
  await desktop.screenshot({ path: `${shots}/${shotPrefix}car-cruising.png` });
  const swing = Math.max(...speeds.slice(40)) - Math.min(...speeds.slice(40));
  assert.ok(swing >= 3, `the faulty cruise should oscillate (swing ${swing} km/h)`);
  await view(desktop, 'diagnostics');
  const faulty = await until('the cruise ECU flagged', async () => {
    const v = await verdict(desktop, 'cruise');
    return v === 'faulty' ? v : null;
  }, 30_000);
  const number = await desktop.getAttribute('[data-testid=verdict-cruise] td:nth-child(3)', 'data-number');
  await desktop.screenshot({ path: `${shots}/${shotPrefix}diagnostics-cruise-faulty.png` });
  ok(`scenario 1: the faulty cruise oscillates (${swing} km/h peak to peak), Diagnostics flags cruise ${faulty} with ${Number(number).toFixed(2)} km/h rms`);
  await view(desktop, 'drive');
  await desktop.keyboard.press('x');
  await brakeToStop(desktop);
  const stoppedAt = await station();
  ok(`scenario 1: the faulty cruise's drive stopped ${stoppedAt} m along the circuit, the simulator steering`);
  await flash(desktop, 'cruise', 'cruise-1.2.0.img');
  await view(desktop, 'drive');
  await until('the wheel', async () => (await desktop.getAttribute('[data-testid=drive-auth]', 'data-ok')) === 'true', 10_000);
  await toStart(desktop);
  await accelerateTo(desktop, 90);
  await desktop.keyboard.press('c');
  await desktop.waitForTimeout(16_000);
  await view(desktop, 'diagnostics');
  const fixed = await until('the cruise verdict back to ok', async () => {
    const v = await verdict(desktop, 'cruise');
    const n = await desktop.getAttribute('[data-testid=verdict-cruise] td:nth-child(3)', 'data-number');
    return v === 'ok' && n ? n : null;
  }, 30_000);
  const routine = await desktop.textContent('[data-testid=verdict-cruise] td:nth-child(5)');
  ok(`scenario 1: with the fix flashed the cruise verdict is ok again (${routine}: ${Number(fixed).toFixed(2)} km/h rms)`);
  await view(desktop, 'drive');
  await desktop.keyboard.press('x');
  await brakeToStop(desktop);

}

/** Report scenario 2 from the page: flash the faulty ABS, brake hard on split friction
 *  (the car spins, the verdict flags the ABS), flash the fix, the same stop is straight. */
async function scenario2(desktop) {
  await flash(desktop, 'abs', 'abs-1.1.0-faulty.img');
  async function hardStopOnSplit() {
    await view(desktop, 'drive');
    await until('the wheel', async () => (await desktop.getAttribute('[data-testid=drive-auth]', 'data-ok')) === 'true', 10_000);
    await toStart(desktop);
    await desktop.click('[data-testid=road-split]');
    await accelerateTo(desktop, 100);
    await brakeToStop(desktop);
    await desktop.click('[data-testid=road-dry]');
  }
  await hardStopOnSplit();
  // The spin on the world view: the heading the simulator reports, and tyre marks.
  await view(desktop, 'drive');
  // The bus's speed is the car's forward speed: a spinning car can show 0 while it still
  // turns and slides. Wait for the simulator's car to come to rest.
  // (A spin from 100 km/h on the split takes several turns: up to a minute.)
  const restFrom = Date.now();
  let lastSeen = null;
  await until('the car at rest', async () => {
    const first = await simPose();
    await desktop.waitForTimeout(300);
    const then = await simPose();
    lastSeen = { speed: then.speed, turned: then.heading - first.heading, moved: Math.hypot(then.x - first.x, then.y - first.y) };
    return Math.abs(then.heading - first.heading) < 0.1 && Math.hypot(then.x - first.x, then.y - first.y) < 0.02;
  }, 60_000).catch((e) => { throw new Error(`${e.message}; last 0.3 s: ${JSON.stringify(lastSeen)}`); });
  const restAfter = (Date.now() - restFrom) / 1000;
  await desktop.waitForTimeout(300);
  const spun = { page: await pagePose(desktop), sim: await simPose() };
  assert.ok(Math.abs(spun.page.heading - spun.sim.heading) <= 3, `the world view shows heading ${spun.page.heading}°, the simulator ${spun.sim.heading.toFixed(1)}°`);
  assert.ok(Math.abs(spun.sim.heading) > 20, `the faulty ABS should turn the car (heading ${spun.sim.heading.toFixed(1)}°)`);
  assert.ok(spun.page.marks > 20, `tyre marks on the world view: ${spun.page.marks} points`);
  await desktop.screenshot({ path: `${shots}/${shotPrefix}world-spin.png` });
  ok(`scenario 2 on the world view: the car stopped turned ${spun.page.heading.toFixed(1)}° (the simulator: ${spun.sim.heading.toFixed(1)}°), ${spun.page.marks} tyre-mark points; at rest ${restAfter.toFixed(1)} s after the bus showed it stopped`);
  await view(desktop, 'diagnostics');
  const absFaulty = await until('the ABS ECU flagged', async () => ((await verdict(desktop, 'abs')) === 'faulty' ? 'faulty' : null), 10_000);
  const absNumber = await desktop.getAttribute('[data-testid=verdict-abs] td:nth-child(3)', 'data-number');
  // The spin was the ABS's doing and the simulator steered through it: the steering ECU
  // only passed on the simulator's hand, which turns the wheel no faster than a hand.
  const steeringVerdict = await verdict(desktop, 'steering');
  assert.ok(steeringVerdict !== 'faulty' && steeringVerdict !== 'suspect', `the steering ECU is judged ${steeringVerdict} after the spin the simulator steered through`);
  ok(`scenario 2: the faulty ABS locks a wheel braking on split friction, Diagnostics flags abs ${absFaulty} with ${Number(absNumber).toFixed(2)} s; the steering the simulator's hand did through the spin leaves the steering ECU ${steeringVerdict}`);
  await flash(desktop, 'abs', 'abs-1.2.0.img');
  await hardStopOnSplit();
  await view(desktop, 'diagnostics');
  const absFixed = await until('the ABS verdict back to ok', async () => {
    const v = await verdict(desktop, 'abs');
    const n = await desktop.getAttribute('[data-testid=verdict-abs] td:nth-child(3)', 'data-number');
    return v === 'ok' && n ? n : null;
  }, 10_000);
  ok(`scenario 2: with the fix flashed the same stop is ok (${Number(absFixed).toFixed(2)} s locked)`);
}

/** A flash the gateway refuses shows its reason on the ECUs view, and keeps it there. */
/** Clicks `selector` and gives the file it downloads, as bytes. */
async function downloaded(page, selector) {
  const [download] = await Promise.all([page.waitForEvent('download', { timeout: 10_000 }), page.click(selector)]);
  return { name: download.suggestedFilename(), bytes: readFileSync(await download.path()) };
}

/**
 * Plots opened late hold the session from its start: the speed chart's first point is at
 * the session's start and it holds the drive to 30 km/h that happened before the page
 * opened (read back from its CSV download); a second signal joins the chart with its own
 * axis; the cursor gives each signal's value at its time; the MCAP download reads back
 * with Foxglove's reader.
 */
async function plotsFromStart(browser) {
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  watch(page);
  await page.goto(`${base}/plots`);
  await page.evaluate(() => localStorage.removeItem('autoplug-plots-charts'));
  await page.reload();
  const chart = '[data-testid=chart-0]';
  await page.waitForSelector(`${chart}[data-points]`, { timeout: 10_000 });
  await page.click('[data-testid=window-session]');
  await until('the speed chart to have its history', async () => Number(await page.getAttribute(chart, 'data-points')) > 100, 10_000);
  const first = Number(await page.getAttribute(chart, 'data-first'));
  const t0 = Number(await page.getAttribute(chart, 'data-start'));
  const now = (await state()).t;
  assert.ok(first - t0 < 1 && now - first > 20, `the chart starts at ${first} s, the session at ${t0} s, now ${now} s`);
  const csv = (await downloaded(page, `${chart} [data-testid=export-csv]`)).bytes.toString();
  const rows = csv.trim().split('\n');
  assert.equal(rows[0], 't_s,VehicleSpeedMsg.VehicleSpeed [km/h]');
  const points = rows.slice(1).map((r) => r.split(',').map(Number));
  const top = Math.max(...points.map(([, v]) => v).filter(Number.isFinite));
  assert.ok(points[0][0] - t0 < 1 && top >= 25, `the CSV runs from ${points[0][0]} s (session from ${t0} s), its top speed ${top} km/h`);
  // A second signal in the same chart: ticked in the picker while chart 1 is the target.
  await page.check('input[data-path="Vehicle.Chassis.Accelerator.PedalPosition"]');
  await until('two signals in the chart', async () => (await page.getAttribute(chart, 'data-paths')) === 'Vehicle.Speed,Vehicle.Chassis.Accelerator.PedalPosition', 5_000);
  await page.waitForSelector(`${chart}[data-points]`);
  await until('the two-signal chart to have its history', async () => Number(await page.getAttribute(chart, 'data-points')) > 100, 10_000);
  const axes = await page.$$eval(`${chart} .u-axis`, (a) => a.length);
  assert.ok(axes >= 3, `time, km/h and % axes: ${axes}`);
  // The cursor: over the chart, each signal's value at the cursor's time.
  const box = await (await page.$(`${chart} .u-over`)).boundingBox();
  await page.mouse.move(box.x + box.width * 0.5, box.y + box.height * 0.5);
  const cursor = await until('the cursor time', async () => {
    const text = await page.textContent(`${chart} [data-testid=cursor-t]`);
    return text.startsWith('t = ') ? text : null;
  }, 5_000);
  const values = await page.$$eval(`${chart} [data-testid=legend-value]`, (v) => v.map((e) => e.textContent));
  assert.equal(values.length, 2);
  assert.ok(values.every((v) => v !== '' && v !== '--'), `values at the cursor: ${values}`);
  await page.screenshot({ path: `${shots}/desktop-plots-history.png` });
  const mcap = await downloaded(page, `${chart} [data-testid=export-mcap]`);
  const reader = await McapIndexedReader.Initialize({ readable: new TempBuffer(mcap.bytes) });
  const topics = [...reader.channelsById.values()].map((c) => c.topic).sort();
  assert.deepEqual(topics, ['/PedalAccel', '/VehicleSpeedMsg']);
  let messages = 0;
  for await (const m of reader.readMessages()) {
    if (messages === 0) assert.ok(JSON.parse(new TextDecoder().decode(m.data)), 'JSON messages');
    messages += 1;
  }
  assert.ok(messages > 100, `${messages} messages in the MCAP`);
  await page.close();
  ok(`a plot opened ${(now - t0).toFixed(0)} s into the session holds it from its start (first point ${first.toFixed(2)} s, the earlier ${top.toFixed(0)} km/h in its CSV), two signals share a chart with an axis each, the cursor gives both values at ${cursor} (${values.join(', ')}), and its MCAP reads back with Foxglove's reader (${topics.join(', ')}, ${messages} messages)`);
}

/** The Bus view: a filter keeps only what matches, in the message list and the trace; the
 *  trace pauses; statistics reset; the bus load is measured; the DBC downloads. */
async function busFilters(page) {
  await view(page, 'bus');
  await until('the bus load', async () => /%$/.test(await page.textContent('[data-testid=bus-load]')), 5_000);
  const load = await page.textContent('[data-testid=bus-load]');
  assert.equal(await page.textContent('[data-testid=fd-frames]'), '0', 'the virtual car\'s classic bus carries no CAN FD frame');
  await page.fill('[data-testid=bus-filter]', 'pedals');
  const visible = async (name) => page.isVisible(`[data-testid=msg-${name}]`);
  await until('the filter to apply', async () => !(await visible('EngineMsg')), 5_000);
  assert.ok(await visible('PedalBrake') && await visible('PedalAccel'), 'the pedals\' messages stay');
  const shown = await page.$$eval('[data-testid=bus-messages] tbody tr:not([hidden])', (rows) => rows.map((r) => r.dataset.testid));
  assert.ok(shown.length >= 2 && shown.length < 10, `rows shown for "pedals": ${shown}`);
  await page.screenshot({ path: `${shots}/desktop-bus-filter.png` });
  await page.click('[data-testid=tab-trace]');
  await until('trace rows', async () => (await page.$$('[data-testid=bus-trace] tbody tr:not([hidden])')).length > 10, 5_000);
  const traced = await page.$$eval('[data-testid=bus-trace] tbody tr:not([hidden])', (rows) => rows.map((r) => r.textContent));
  assert.ok(traced.every((t) => /pedal/i.test(t)), `every trace row shown matches: ${traced.slice(0, 3)}`);
  const hidden = await page.$$eval('[data-testid=bus-trace] tbody tr[hidden]', (rows) => rows.length);
  assert.ok(hidden > 0, 'the trace held other frames the filter hides');
  await page.click('[data-testid=bus-pause]');
  await page.waitForTimeout(400);
  const pausedAt = await page.getAttribute('[data-testid=bus-trace]', 'data-last');
  await page.waitForTimeout(800);
  assert.equal(await page.getAttribute('[data-testid=bus-trace]', 'data-last'), pausedAt, 'paused, the trace stands');
  await page.click('[data-testid=bus-pause]');
  await until('the trace to go on', async () => (await page.getAttribute('[data-testid=bus-trace]', 'data-last')) !== pausedAt, 5_000);
  await page.screenshot({ path: `${shots}/desktop-bus-trace.png` });
  await page.click('[data-testid=tab-messages]');
  await page.fill('[data-testid=bus-filter]', '');
  const framesBefore = Number(await page.textContent('[data-testid=bus-frames]'));
  await page.click('[data-testid=bus-reset]');
  const framesAfter = Number(await page.textContent('[data-testid=bus-frames]'));
  assert.ok(framesAfter < framesBefore / 10, `frames ${framesBefore} before the reset, ${framesAfter} after`);
  const dbc = await downloaded(page, '[data-testid=dbc-download]');
  assert.equal(dbc.name, 'autoplug.dbc');
  assert.match(dbc.bytes.toString(), /BO_ 3 VehicleSpeedMsg/);
  ok(`the Bus view filters ("pedals": ${shown.length} messages, and only their frames in the trace), its trace pauses and goes on, its statistics reset (${framesBefore} → ${framesAfter} frames), the bus load reads ${load}, the DBC downloads (${dbc.bytes.length} bytes)`);
}

async function refusedFlash(desktop) {
  const logged = problems.length;
  await view(desktop, 'ecus');
  await desktop.selectOption('[data-testid=flash-image]', 'abs-1.2.0.img');
  await desktop.selectOption('[data-testid=flash-ecu]', 'cruise');
  await desktop.click('[data-testid=flash-start]');
  const shown = await until('the refusal on the page', async () => {
    const text = await desktop.textContent('[data-testid=flash-status]');
    return text?.startsWith('Refused: ') ? text : null;
  }, 5_000);
  assert.match(shown, /not for cruise/);
  // Two session updates later (they come twice a second) the reason is still there.
  await desktop.waitForTimeout(1500);
  assert.equal(await desktop.textContent('[data-testid=flash-status]'), shown);
  // Chromium logs the refused request (409) as a console error: this one was asked for.
  const asked = problems.slice(logged).filter((p) => /status of 409/.test(p));
  assert.equal(asked.length, 1, `the refusal's console line: ${problems.slice(logged).join('\n')}`);
  problems.splice(problems.indexOf(asked[0]), 1);
  ok(`a refused flash says why on the page, and keeps saying it: "${shown}"`);
}

await run(async () => {
  startPose = await until('the car in the simulator\'s world', simPose, 15_000);
  if (onFirmware) {
    const desktop = await browser.newPage({ viewport: { width: 1280, height: 900 } });
    watch(desktop);
    await desktop.goto(`${base}/car#token=${token}`);
    await desktop.waitForSelector('[data-testid=speed][data-value]', { timeout: 15_000 });
    // The library holds the releases the dashboard built, nothing prepared by hand.
    const library = (await (await fetch(`${base}/api/images`)).json()).map((i) => i.name).sort();
    assert.deepEqual(library, ['abs-1.1.0-faulty.img', 'abs-1.2.0.img', 'cruise-1.1.0-faulty.img', 'cruise-1.2.0.img']);
    ok(`the library holds the releases the dashboard built: ${library.join(', ')}`);
    await scenario1(desktop);
    await scenario2(desktop);
    await view(desktop, 'ecus');
    await desktop.waitForTimeout(500);
    await desktop.screenshot({ path: `${shots}/firmware-ecus.png` });
    assert.deepEqual(problems, [], `the pages logged errors:\n${problems.join('\n')}`);
    ok('no console errors');
    return;
  }
  // Without the token, a write is refused.
  const refused = await fetch(`${base}/api/recording`, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: '{"on":true}' });
  assert.equal(refused.status, 401);
  const wrong = await fetch(`${base}/api/recording`, { method: 'POST', headers: { 'Content-Type': 'application/json', Authorization: 'Bearer wrong-token-wrong-token' }, body: '{"on":true}' });
  assert.equal(wrong.status, 401);
  const malformed = await fetch(`${base}/api/recording`, { method: 'POST', headers: { 'Content-Type': 'application/json', Authorization: `Bearer ${token}` }, body: '{"on":' });
  assert.equal(malformed.status, 400);
  assert.match((await malformed.json()).error, /body/);
  ok('writes without the token are refused (401), a malformed body gets 400 with the reason');

  const desktop = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  watch(desktop);
  await desktop.goto(`${base}/car#token=${token}`);
  await desktop.waitForSelector('[data-testid=speed][data-value]', { timeout: 15_000 });
  for (const name of Object.keys(VIEWS)) {
    await view(desktop, name);
    await desktop.waitForTimeout(500);
    await desktop.screenshot({ path: `${shots}/desktop-${name}.png` });
  }
  ok('every view renders (desktop screenshots written)');

  // A routine that has had nothing to judge says so: cruise was never engaged yet.
  await view(desktop, 'diagnostics');
  const unexercised = await until('cruise judged not exercised', async () => ((await verdict(desktop, 'cruise')) === 'not exercised' ? 'not exercised' : null), 5_000);
  const why = await desktop.textContent('[data-testid=verdict-cruise] td:nth-child(6)');
  assert.match(why, /^not exercised/);
  ok(`a routine never exercised shows "${unexercised}", not OK (cruise: ${why})`);

  // Record what follows, from the page.
  await view(desktop, 'recordings');
  await desktop.click('[data-testid=record]');
  await until('the recording to run', async () => (await desktop.textContent('[data-testid=recording-state]')).startsWith('●'), 5_000);

  // Driving: the accelerator raises the speed, the brake lights follow the brake.
  await view(desktop, 'drive');
  await until('the wheel to be ours', async () => (await desktop.getAttribute('[data-testid=drive-auth]', 'data-ok')) === 'true', 10_000);
  const before = await speedNow();
  await accelerateTo(desktop, 30);
  ok(`the accelerator on the page raised the speed from ${before} to ${await speedNow()} km/h`);

  // The world view beside the controls: the car on its road, moving as the simulator
  // moves it, drawn smoothly.
  await desktop.keyboard.down('ArrowUp');
  const a = { page: await pagePose(desktop), sim: await simPose() };
  // Where the simulator had the car at the moment the page showed it (read now, while
  // the world channel surely holds that moment).
  const simAtA = await simPoseAt(a.page.t);
  const rates = [];
  for (let i = 0; i < 6; i++) {
    await desktop.waitForTimeout(400);
    rates.push((await pagePose(desktop)).fps);
  }
  const b = { page: await pagePose(desktop), sim: await simPose() };
  await desktop.keyboard.up('ArrowUp');
  // Along the road: each pose on the road (within its half width of the centreline),
  // the later ones further along it, on the page as in the simulator.
  const road = await worldRoad();
  assert.ok(road, 'the dashboard car has a road');
  const along = [a.page, b.page, a.sim, b.sim].map((p) => onRoad(road, p));
  for (const [i, place] of along.entries()) {
    assert.ok(place.off < road.width_m / 2, `pose ${i} is ${place.off.toFixed(1)} m from the centreline of ${road.name}`);
  }
  assert.ok(along[1].station > along[0].station + 10 && along[3].station > along[2].station + 10,
    `along ${road.name}: the page ${along[0].station} → ${along[1].station} m, the simulator ${along[2].station} → ${along[3].station} m`);
  const movedSim = Math.hypot(b.sim.x - a.sim.x, b.sim.y - a.sim.y);
  const movedPage = Math.hypot(b.page.x - a.page.x, b.page.y - a.page.y);
  // Where the simulator had the car at the moment the page shows (the page draws a little
  // behind the channel, to interpolate; the two reads are not simultaneous either).
  const simAt = await simPoseAt(b.page.t);
  assert.ok(simAt && simAtA, `the world channel still holds the simulator's poses at ${a.page.t} and ${b.page.t} s`);
  const gap = Math.hypot(b.page.x - simAt.x, b.page.y - simAt.y);
  assert.ok(movedSim > 10, `the simulator's car moved ${movedSim.toFixed(1)} m`);
  // The page's movement against the simulator's between the same two moments: the page
  // and the simulator are read one after the other, and while the car accelerates a few
  // tenths of a second between two reads are metres (a CI run saw 56.6 m against 61.2 m
  // comparing the reads themselves).
  const movedSimShown = Math.hypot(simAt.x - simAtA.x, simAt.y - simAtA.y);
  assert.ok(Math.abs(movedPage - movedSimShown) < 3, `the page moved the car ${movedPage.toFixed(1)} m, the simulator ${movedSimShown.toFixed(1)} m between the same moments (${movedSim.toFixed(1)} m between the reads)`);
  assert.ok(gap < 1, `the page's car at ${b.page.t} s is ${gap.toFixed(2)} m from where the simulator had it then`);
  const fps = Math.min(...rates.slice(1));
  assert.ok(fps >= 30, `the world view drew ${rates.join(', ')} frames/s while the car moved`);
  await desktop.screenshot({ path: `${shots}/desktop-world-top.png` });
  await desktop.click('[data-testid=world-chase]');
  await desktop.waitForTimeout(500);
  await desktop.screenshot({ path: `${shots}/desktop-world-chase.png` });
  await desktop.click('[data-testid=world-top]');
  ok(`the world view follows the simulator along ${road.name} (station ${along[0].station} → ${along[1].station} m on the page, ${along[2].station} → ${along[3].station} m in the simulator): the car moved ${movedPage.toFixed(1)} m on the page as it moved ${movedSimShown.toFixed(1)} m in the simulator between the same moments (at the end the page drew the car ${gap.toFixed(2)} m from where the simulator had it at the moment shown); ${fps} frames/s at the least while it moved (${rates.join(', ')})`);

  // The Car view follows the bus: within 1 km/h of the last VehicleSpeedMsg, within 200 ms.
  const drivingTab = desktop;
  const watcher = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  watch(watcher);
  await watcher.goto(`${base}/car`);
  await watcher.waitForSelector('[data-testid=speed][data-value]');
  await drivingTab.bringToFront();
  await drivingTab.keyboard.down('ArrowUp');
  const lags = [];
  // One round first, not counted: right after the tab switch it measures the new page
  // settling in the background (once, 312 ms on a busy 2-core machine), not the stream.
  for (let i = 0; i < 16; i++) {
    const sent = Date.now();
    const onBus = (await state()).signals['Vehicle.Speed'];
    await until('the page to show the bus speed', async () => {
      const shown = await shownSpeed(watcher);
      return Math.abs(shown - onBus) <= 1 || shown > onBus;
    }, 2_000);
    if (i > 0) lags.push(Date.now() - sent);
    await new Promise((r) => setTimeout(r, 150));
  }
  await drivingTab.keyboard.up('ArrowUp');
  const worst = Math.max(...lags);
  assert.ok(worst <= 200, `the Car view took ${worst} ms to show the speed on the bus (lags ${lags.join(', ')} ms)`);
  ok(`the Car view follows the bus: the shown speed reached the bus's within ${worst} ms (15 samples while accelerating: ${lags.join(', ')} ms)`);

  await drivingTab.keyboard.down('ArrowDown');
  await until('the brake lights on the Car view', async () => (await watcher.getAttribute('[data-testid=brake-lights]', 'data-on')) === 'true', 3_000);
  await until('the car to stop', async () => (await speedNow()) < 0.5, 60_000);
  await drivingTab.keyboard.up('ArrowDown');
  await watcher.waitForTimeout(300);
  const standing = (await state()).signals['Vehicle.Speed'];
  assert.ok(Math.abs((await shownSpeed(watcher)) - standing) <= 1, 'the Car view shows the speed on the bus');
  await until('the brake lights off', async () => (await watcher.getAttribute('[data-testid=brake-lights]', 'data-on')) === 'false', 3_000);
  ok('the brake lights on the Car view follow the brake pressed on the page');
  await watcher.close();
  await brakeToStop(desktop);

  // Held controls cannot stick. A key held while the person switches views stays held
  // (the brake while flashing); the page losing the keyboard releases it on the bus at
  // once, and so does a driving page that goes away.
  const busBrake = async () => (await state()).signals['Vehicle.Chassis.Brake.PedalPosition'] ?? null;
  await until('the brake on the bus', async () => (await busBrake()) > 50, 3_000);
  await view(desktop, 'ecus');
  await desktop.waitForTimeout(1500);
  assert.ok((await busBrake()) > 50, 'a key held while switching views stays held');
  await desktop.evaluate(() => window.dispatchEvent(new Event('blur')));
  const blurredAt = Date.now();
  await until('the brake released on the bus', async () => (await busBrake()) < 1, 2_000);
  const blurRelease = Date.now() - blurredAt;
  await desktop.keyboard.up('ArrowDown');
  await view(desktop, 'drive');
  const told = await until('the Drive view to say why', async () => {
    const text = await desktop.textContent('[data-testid=drive-released]');
    return text ? text : null;
  }, 2_000);
  assert.match(told, /released: the window lost the keyboard/);
  // Out of the Drive view with nothing held, this page sends nothing: the other drives.
  await view(desktop, 'ecus');
  const other = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  watch(other);
  await other.goto(`${base}/drive#token=${token}`);
  await until('the second page\'s wheel', async () => (await other.getAttribute('[data-testid=drive-auth]', 'data-ok')) === 'true', 10_000);
  await other.keyboard.down('ArrowDown');
  await until('the second page\'s brake on the bus', async () => (await busBrake()) > 50, 3_000);
  await other.close();
  const closedAt = Date.now();
  await until('the brake released when the page went away', async () => (await busBrake()) < 1, 3_000);
  const closeRelease = Date.now() - closedAt;
  ok(`held controls are released on the bus: ${blurRelease} ms after the page lost the keyboard ("${told}"), ${closeRelease} ms after a driving page closed; a key held across a change of view stayed held`);
  await desktop.bringToFront();
  await view(desktop, 'drive');
  await brakeToStop(desktop);
  await plotsFromStart(browser);
  await busFilters(desktop);

  // The recording replays in a dashboard of its own: play, pause, seek.
  await view(desktop, 'recordings');
  await desktop.click('[data-testid=record]');
  const replayId = await until('the recording listed', async () => {
    const button = await desktop.$('button[data-testid^="open-replay-"]');
    return button ? button.getAttribute('data-testid') : null;
  }, 5_000);
  const [replayPage] = await Promise.all([
    desktop.waitForEvent('popup', { timeout: 15_000 }),
    desktop.click(`[data-testid="${replayId}"]`),
  ]);
  watch(replayPage);
  await replayPage.waitForSelector('[data-testid=replay-play]', { state: 'visible', timeout: 15_000 });
  // Where the replay's gateway says it is (the page's position text, from its session).
  const position = async () => parseFloat(await replayPage.textContent('[data-testid=replay-position]'));
  const p1 = await position();
  await replayPage.waitForTimeout(1500);
  const p2 = await position();
  assert.ok(p2 > p1, `the replay plays (${p1} -> ${p2} s)`);
  await replayPage.click('[data-testid=replay-play]');
  // The session's state comes twice a second: read it after one written after the pause.
  await replayPage.waitForTimeout(1200);
  const p3 = await position();
  await replayPage.waitForTimeout(1000);
  assert.equal(await position(), p3, 'paused, the position stands');
  await replayPage.$eval('[data-testid=replay-seek]', (e) => { e.value = '1'; e.dispatchEvent(new Event('change')); });
  await until('the seek', async () => Math.abs((await position()) - 1) < 0.2, 5_000);
  // Paused after the jump, the page shows the car as it was there.
  await until('the speed at the new position', async () => (await replayPage.getAttribute('[data-testid=speed]', 'data-value')) !== '', 5_000);
  await replayPage.screenshot({ path: `${shots}/desktop-replay.png` });
  // The replay's world: the recording's world file played with its frames, the car on
  // the circuit where it was at 1 s.
  await view(replayPage, 'drive');
  const replayed = await pagePose(replayPage);
  const replayedRoad = await worldRoad(new URL(replayPage.url()).origin);
  assert.ok(replayedRoad, 'the replay has the recording\'s world');
  const replayedOn = onRoad(replayedRoad, replayed);
  assert.ok(replayedOn.off < 5, `the replayed car is ${replayedOn.off.toFixed(1)} m from the circuit's centreline`);
  // A replay cannot be driven: its Drive view shows the world and says so, no controls.
  await until('the replay\'s Drive view to say it cannot be driven', async () => /replay/i.test(await replayPage.textContent('[data-testid=drive-auth]')), 5_000);
  assert.ok(!(await replayPage.isVisible('[data-testid=pedal-accelerator]')), 'a replay shows no pedals');
  await replayPage.screenshot({ path: `${shots}/desktop-replay-world.png` });
  await replayPage.click('[data-testid=replay-play]');
  await view(replayPage, 'bus');
  const replayLoad = await until('the replay\'s bus load', async () => {
    const text = await replayPage.textContent('[data-testid=bus-load]');
    return /^[0-9.]+ %$/.test(text) && parseFloat(text) > 1 ? text : null;
  }, 10_000);
  await replayPage.close();
  ok(`the recording made from the page replays in a dashboard of its own: it played (${p1.toFixed(1)} -> ${p2.toFixed(1)} s), paused at ${p3.toFixed(1)} s, jumped to 1 s; its world view shows the car on the circuit at station ${replayedOn.station} m, its Bus view a bus load of ${replayLoad}`);

  await refusedFlash(desktop);
  await scenario1(desktop);

  await scenario2(desktop);

  // A verdict can be reset per ECU: the ABS is judged again from now on, and with no hard
  // braking since, it is not exercised.
  await view(desktop, 'diagnostics');
  await desktop.click('[data-testid=reset-verdict-abs]');
  const afterReset = await until('the ABS judged again', async () => {
    const v = await verdict(desktop, 'abs');
    return v === 'not exercised' ? v : null;
  }, 5_000);
  assert.equal(await verdict(desktop, 'cruise'), 'ok', 'a reset of the ABS leaves the cruise verdict');
  ok(`a verdict is reset per ECU from the page: abs ${afterReset} after its reset, cruise still ok`);

  // The trip under way shows the verdicts and codes the Diagnostics view lists.
  await view(desktop, 'trips');
  const tripVerdicts = await until('the trip\'s verdicts', async () => {
    const items = await desktop.$$eval('[data-testid=current-verdicts] li', (li) => li.map((e) => [e.dataset.ecu, e.querySelector('.verdict').textContent]));
    return items.length === 9 ? items : null;
  }, 5_000);
  const tripCruise = tripVerdicts.find(([ecu]) => ecu === 'cruise')?.[1];
  assert.equal(tripCruise, 'ok', `the trip's verdicts: ${JSON.stringify(tripVerdicts)}`);
  assert.equal(tripVerdicts.find(([ecu]) => ecu === 'abs')?.[1], 'not exercised');
  await desktop.screenshot({ path: `${shots}/desktop-trip-verdicts.png` });
  ok(`the trip under way shows the nine verdicts as Diagnostics has them (cruise ${tripCruise}, abs not exercised) and its trouble codes`);

  // A phone: the Car view fits without horizontal scrolling; every view renders.
  const phone = await browser.newPage({ viewport: { width: 390, height: 844 }, deviceScaleFactor: 2, isMobile: true, hasTouch: true });
  watch(phone);
  await phone.goto(`${base}/car#token=${token}`);
  await phone.waitForSelector('[data-testid=speed][data-value]');
  const width = await phone.evaluate(() => document.documentElement.scrollWidth);
  assert.ok(width <= 390, `the Car view is ${width} px wide on a 390 px phone`);
  for (const name of Object.keys(VIEWS)) {
    await view(phone, name);
    await phone.waitForTimeout(400);
    await phone.screenshot({ path: `${shots}/phone-${name}.png` });
  }
  ok(`on a phone (390 × 844) the Car view fits (${width} px), every view renders (phone screenshots written)`);
  await view(phone, 'drive');
  await pagePose(phone);
  await phone.waitForTimeout(1200);
  const onPhone = await pagePose(phone);
  assert.ok(onPhone.fps >= 30, `the world view drew ${onPhone.fps} frames/s on the phone`);
  const canvasWidth = await phone.$eval('[data-testid=world-canvas]', (c) => c.getBoundingClientRect().width);
  const phoneWidth = await phone.evaluate(() => document.documentElement.scrollWidth);
  assert.ok(canvasWidth > 300 && phoneWidth <= 390, `the world view is ${canvasWidth} px wide on the phone, the page ${phoneWidth} px`);
  await phone.screenshot({ path: `${shots}/phone-world.png` });
  ok(`on a phone the world view fits (${canvasWidth.toFixed(0)} px wide, ${onPhone.fps} frames/s)`);
  // The phone's whole layout: every view's name in sight, and on Drive the road, the speed
  // and both pedals on one screen.
  const links = await phone.$$eval('nav a', (a) => a.map((e) => { const r = e.getBoundingClientRect(); return [e.textContent, r.right, r.bottom]; }));
  assert.ok(links.every(([, right, bottom]) => right <= 390 && bottom <= 844), `navigation on the phone: ${JSON.stringify(links)}`);
  const below = await phone.$$eval('[data-testid=pedal-brake], [data-testid=pedal-accelerator], [data-testid=world-canvas], [data-testid=drive-speed]',
    (els) => els.map((e) => [e.dataset.testid, Math.round(e.getBoundingClientRect().bottom)]).filter(([, bottom]) => bottom > innerHeight));
  assert.deepEqual(below, [], 'on the phone\'s Drive view nothing of the road, the speed or the pedals is below the fold');
  // The friction in force, shown on its button.
  await phone.click('[data-testid=road-split]');
  await until('Split µ shown in force', async () => (await phone.getAttribute('[data-testid=road-split]', 'aria-pressed')) === 'true', 5_000);
  assert.equal(await phone.getAttribute('[data-testid=road-dry]', 'aria-pressed'), 'false');
  // The driver's view in 3-D at the phone's size, chase camera and driver's seat.
  // The view draws coarser a step at a time while its frames come slowly (this machine's
  // WebGL is software): its rate is read once its resolution has held for 1.5 s, so the
  // second counted was drawn at the resolution it settled on.
  const rates3d = {};
  const ratios3d = {};
  for (const camera of ['chase', 'cockpit']) {
    await phone.click(`[data-testid=world-${camera}]`);
    await until(`the ${camera} view drawn in 3-D`, async () => Number(await phone.getAttribute('[data-testid=world]', 'data-triangles')) > 100, 15_000);
    ratios3d[camera] = await until(`the ${camera} view's resolution settled`, async () => {
      const before = await phone.getAttribute('[data-testid=world]', 'data-pixel-ratio');
      await phone.waitForTimeout(1500);
      const after = await phone.getAttribute('[data-testid=world]', 'data-pixel-ratio');
      return before === after ? Number(after) : null;
    }, 15_000);
    rates3d[camera] = Number(await phone.getAttribute('[data-testid=world]', 'data-fps'));
    await phone.screenshot({ path: `${shots}/phone-world-${camera}.png` });
  }
  const triangles = await phone.getAttribute('[data-testid=world]', 'data-triangles');
  assert.ok(rates3d.chase >= 30 && rates3d.cockpit >= 30, `the 3-D view on the phone: ${JSON.stringify(rates3d)} frames/s at pixel ratios ${JSON.stringify(ratios3d)}`);
  await phone.click('[data-testid=road-dry]');
  await phone.click('[data-testid=world-top]');
  ok(`on the phone the navigation is whole and Drive has the road, the speed and the pedals on one screen; Split µ shows in force; the 3-D view draws ${triangles} triangles at ${rates3d.chase} frames/s (chase, pixel ratio ${ratios3d.chase}) and ${rates3d.cockpit} frames/s (driver's seat, ${ratios3d.cockpit})`);

  // Dark mode.
  await desktop.emulateMedia({ colorScheme: 'dark' });
  await view(desktop, 'car');
  await desktop.waitForTimeout(300);
  await desktop.screenshot({ path: `${shots}/desktop-car-dark.png` });
  ok('dark mode screenshot written');

  assert.deepEqual(problems, [], `the pages logged errors:\n${problems.join('\n')}`);
  ok('no console errors on any page');
});
console.log(`dashboard: ${count()} checks passed`);
