// The fleet's update reaching a driver, in a real Chromium (Debian's, headless, through
// playwright-core), against a running `autoplug dashboard --fleet ... --fleet-db ...` on
// the virtual car and `autoplug fleet serve --web` on the same fleet database, over the
// real MQTT broker:
// - the car is driven from the page; the campaign is created while it drives;
// - on a phone-sized page the driver is asked "An update for your cruise control is ready:
//   install when parked?" and answers Install; nothing is flashed while the car moves;
// - braked to a stop, the update installs over CAN; the page says so, the ECUs view shows
//   the new version;
// - the Fleet view (the dashboard's, and the fleet service's own page) shows the campaign
//   finished, the vehicle installed and running the new version;
// - the consent is refused without the token, and for a campaign not offered.
// Screenshots of each step go to SCREENSHOT_DIR.
//
// node tests/fleet.mjs DASHBOARD_URL TOKEN FLEET_PAGE_URL SCREENSHOT_DIR -- AUTOPLUG CAMPAIGN_ARGS...
//   (AUTOPLUG CAMPAIGN_ARGS...: the command that creates the campaign)

import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdirSync } from 'node:fs';
import { launchChromium, steps, until } from './harness.mjs';

const args = process.argv.slice(2);
const split = args.indexOf('--');
const [base, token, fleetPage, shots] = args.slice(0, split);
const create = args.slice(split + 1);
if (!base || !token || !fleetPage || !shots || split < 0 || create.length === 0) {
  console.error('usage: node tests/fleet.mjs DASHBOARD_URL TOKEN FLEET_PAGE_URL SCREENSHOT_DIR -- AUTOPLUG CAMPAIGN_ARGS...');
  process.exit(2);
}
mkdirSync(shots, { recursive: true });

const browser = await launchChromium();
const { ok, watch, problems, run, count } = steps(browser);

async function session() {
  return (await (await fetch(`${base}/api/state`)).json()).session;
}

async function speedNow() {
  return (await (await fetch(`${base}/api/state`)).json()).signals['Vehicle.Speed'] ?? 0;
}

function cruiseVersion(s) {
  return s.inventory.find((row) => row.ecu === 'cruise')?.software_version;
}

await run(async () => {
  const s0 = await until('the VIN read and the fleet link up', async () => {
    const s = await session();
    return s?.fleet?.vin && s.fleet.connected && cruiseVersion(s) ? s : null;
  }, 30_000);
  const vin = s0.fleet.vin;
  const before = cruiseVersion(s0);
  await until('the fleet to know the vehicle', async () => {
    const fleet = await (await fetch(`${fleetPage}/api/fleet`)).json();
    return fleet.summary.vehicles >= 1;
  }, 30_000);
  ok(`the gateway reads the VIN ${vin} and reports to the fleet (cruise runs ${before})`);

  // The driver drives off (the desktop page's Drive view, the keyboard's pedals).
  const desktop = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  watch(desktop);
  await desktop.goto(`${base}/drive#token=${token}`);
  await until('the wheel', async () => (await desktop.getAttribute('[data-testid=drive-auth]', 'data-ok')) === 'true', 10_000);
  await desktop.keyboard.down('ArrowUp');
  await until('60 km/h', async () => (await speedNow()) >= 60, 60_000);
  await desktop.keyboard.up('ArrowUp');
  // The pedal springs back before the cruise control is switched on (a pressed pedal
  // cancels it); the cruise then holds the speed while the driver answers.
  await desktop.waitForTimeout(700);
  await desktop.keyboard.press('c');
  await until('cruise on', async () => (await (await fetch(`${base}/api/state`)).json()).signals['Vehicle.ADAS.CruiseControl.IsActive'] === 1, 5_000);
  ok(`the car is driven from the page, cruising at ${(await speedNow()).toFixed(0)} km/h`);

  // The manufacturer starts the campaign while the car drives.
  const created = execFileSync(create[0], create.slice(1), { encoding: 'utf8' });
  assert.match(created, /campaign \d+ '[^']+': 1 vehicle\(s\)/);
  const campaign = Number(/campaign (\d+)/.exec(created)[1]);
  ok(`campaign ${campaign} created for the car: ${created.trim().split('\n').pop()}`);

  // The driver's phone.
  const phone = await browser.newPage({ viewport: { width: 390, height: 844 }, deviceScaleFactor: 2, isMobile: true, hasTouch: true });
  watch(phone);
  await phone.goto(`${base}/car#token=${token}`);
  await desktop.bringToFront();
  await phone.waitForSelector('[data-testid=offer-install]', { state: 'visible', timeout: 60_000 });
  const question = await phone.textContent('[data-testid=offer-question]');
  assert.equal(question, 'An update for your cruise control is ready: install when parked?');
  const width = await phone.evaluate(() => document.documentElement.scrollWidth);
  assert.ok(width <= 390, `the page is ${width} px wide on a 390 px phone`);
  const box = await phone.locator('[data-testid=offer]').boundingBox();
  assert.ok(box && box.x >= 0 && box.x + box.width <= 390, `the offer sits outside the screen: ${JSON.stringify(box)}`);
  await phone.screenshot({ path: `${shots}/phone-fleet-offer.png` });
  ok(`the phone asks: "${question}" (the page ${width} px wide)`);

  // Without the token, and for a campaign not offered, the answer is refused.
  const anonymous = await fetch(`${base}/api/fleet/consent`, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify({ campaign, install: true }) });
  assert.equal(anonymous.status, 401);
  const other = await fetch(`${base}/api/fleet/consent`, { method: 'POST', headers: { 'Content-Type': 'application/json', Authorization: `Bearer ${token}` }, body: JSON.stringify({ campaign: campaign + 1000, install: true }) });
  assert.equal(other.status, 409);
  assert.match((await other.json()).error, /no update of campaign/);
  const malformed = await fetch(`${base}/api/fleet/consent`, { method: 'POST', headers: { 'Content-Type': 'application/json', Authorization: `Bearer ${token}` }, body: '{"campaign":"x"}' });
  assert.equal(malformed.status, 422);
  ok('a consent without the token gets 401, for a campaign not offered 409 with the reason, a malformed one 422');

  // Install: while the car moves, it waits.
  assert.ok((await speedNow()) > 5, 'the car should still be moving');
  await phone.click('[data-testid=offer-install]');
  await until('the page to say it waits for the car to be parked', async () => /parked/.test(await phone.textContent('[data-testid=offer-state]')), 10_000);
  await phone.screenshot({ path: `${shots}/phone-fleet-waiting.png` });
  await phone.waitForTimeout(2000);
  const moving = await session();
  assert.equal(moving.fleet.activity?.what, 'waiting for the car to stand still');
  assert.equal(moving.flash, null);
  assert.ok(!/flash/i.test(moving.tester ?? ''), `the tester flashes while the car moves: ${moving.tester}`);
  assert.equal(cruiseVersion(moving), before);
  ok(`Install answered while driving at ${(await speedNow()).toFixed(0)} km/h: nothing flashed, "${await phone.textContent('[data-testid=offer-state]')}"`);

  // Brake to a stop: the update goes over CAN, then the page says it is done.
  await desktop.bringToFront();
  await desktop.keyboard.press('x');
  await desktop.keyboard.down('ArrowDown');
  await until('the car to stop', async () => (await speedNow()) < 0.5, 60_000);
  await until('the flash to start', async () => (await session()).fleet.activity?.what === 'flashing', 30_000);
  await phone.screenshot({ path: `${shots}/phone-fleet-installing.png` });
  const done = await until('the update installed', async () => {
    const s = await session();
    const last = s.fleet.reports.at(-1);
    if (last && ['refused', 'failed'].includes(last.state)) throw new Error(`the update ${last.state}: ${last.reason}`);
    return last?.state === 'installed' && !s.fleet.activity ? s : null;
  }, 120_000);
  await desktop.keyboard.up('ArrowDown');
  const after = done.fleet.reports.at(-1).version_running;
  assert.notEqual(after, before);
  await phone.waitForSelector('[data-testid=offer-dismiss]', { state: 'visible' });
  assert.match(await phone.textContent('[data-testid=offer-question]'), /up to date/);
  assert.match(await phone.textContent('[data-testid=offer-detail]'), new RegExp(`now running ${after.replace(/\./g, '\\.')}`));
  await phone.screenshot({ path: `${shots}/phone-fleet-installed.png` });
  await until(`the ECUs view's inventory to show cruise ${after}`, async () => cruiseVersion(await session()) === after, 15_000);
  ok(`stopped: the update installed over CAN, cruise runs ${after} (was ${before}); the phone says so`);
  await phone.click('[data-testid=offer-dismiss]');
  assert.ok(await phone.isHidden('[data-testid=offer]'));

  // The manufacturer's view: the dashboard's Fleet view and the fleet service's own page.
  await desktop.goto(`${base}/fleet`);
  const row = `[data-testid=campaign-${campaign}]`;
  await until('the campaign finished on the Fleet view', async () => {
    await desktop.waitForSelector(row);
    return /finished/.test(await desktop.textContent(row)) && /1 \/ 1 installed/.test(await desktop.textContent(row));
  }, 30_000);
  const vehicle = desktop.locator(`[data-testid=fleet-vehicles] tr[data-vin=${vin}]`);
  await vehicle.waitFor();
  const cells = await vehicle.locator('td').allTextContents();
  assert.equal(cells[2], 'installed');
  assert.equal(cells[4], after);
  await desktop.screenshot({ path: `${shots}/desktop-fleet.png` });
  ok(`the Fleet view: campaign ${campaign} finished, 1 / 1 installed; ${vin} installed, running ${after}`);

  const service = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  watch(service);
  await service.goto(`${fleetPage}/`);
  await service.waitForSelector(row);
  const nav = await service.locator('nav a').allTextContents();
  assert.deepEqual(nav, ['Fleet']);
  assert.match(await service.textContent(row), /finished/);
  await service.screenshot({ path: `${shots}/desktop-fleet-service.png` });
  const phoneFleet = await browser.newPage({ viewport: { width: 390, height: 844 }, deviceScaleFactor: 2, isMobile: true, hasTouch: true });
  watch(phoneFleet);
  await phoneFleet.goto(`${fleetPage}/fleet`);
  await phoneFleet.waitForSelector(row);
  await phoneFleet.screenshot({ path: `${shots}/phone-fleet-service.png` });
  ok('the fleet service\'s own page shows only the Fleet view, with the same campaign');

  assert.deepEqual(problems, [], `the pages logged errors:\n${problems.join('\n')}`);
  ok('no console errors on any page');
});
console.log(`fleet: ${count()} checks passed`);
