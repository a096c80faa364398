// A debugger on an emulated ECU of the dashboard's car, seen from the page: Debian's
// gdb-multiarch attaches to the cruise ECU's GDB server (`autoplug dashboard --firmware …
// --gdb cruise=ADDR`) and stops at its control step; the page says the car is halted by the
// debugger, the bus time stands still, an action is refused with the reason, and no
// verdict changes; after the detach the car runs on at its pace (no catching up on the
// pause) and the page says so.
//
// node tests/debugger.mjs BASE_URL TOKEN GDB_ADDR ELF SCREENSHOT_DIR

import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import { existsSync, mkdirSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { launchChromium, steps, until } from './harness.mjs';

const [base, token, gdbAddr, elf, shots] = process.argv.slice(2);
if (!base || !token || !gdbAddr || !elf || !shots) {
  console.error('usage: node tests/debugger.mjs BASE_URL TOKEN GDB_ADDR ELF SCREENSHOT_DIR');
  process.exit(2);
}
mkdirSync(shots, { recursive: true });
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function state() {
  const response = await fetch(`${base}/api/state`);
  assert.equal(response.status, 200, 'GET /api/state');
  return response.json();
}
const verdicts = (s) => Object.fromEntries((s.session?.diagnostics ?? []).map((d) => [d.ecu, d.verdict]));

const browser = await launchChromium();
const t = steps(browser);
const work = mkdtempSync(join(tmpdir(), 'debugger-test-'));
let gdb = null;
await t.run(async () => {
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  t.watch(page);
  await page.goto(`${base}/car#token=${token}`);
  const bar = page.locator('[data-testid=debugger]');
  await until('the debugger bar naming the GDB server', async () => (await bar.isVisible()) && (await bar.textContent()).includes(`cruise: GDB server on ${gdbAddr}`), 20_000);
  t.ok(`the page names cruise's GDB server (${gdbAddr})`);

  // Running for a while first: the verdicts the pause must leave alone.
  const start = await state();
  await until('the car running', async () => (await state()).t > start.t + 1, 20_000);
  const before = verdicts(await state());

  // gdb-multiarch stops at the control step and holds the car until told to go on.
  const halted = join(work, 'halted');
  const resume = join(work, 'resume');
  let output = '';
  gdb = spawn('gdb-multiarch', ['-batch', '-nx', elf,
    '-ex', 'set pagination off', '-ex', 'set confirm off',
    '-ex', `target extended-remote ${gdbAddr}`,
    '-ex', 'break runtime.rs:246', '-ex', 'continue',
    // At most a minute: a test that failed meanwhile leaves no gdb behind.
    '-ex', `shell touch ${halted}; for i in $(seq 600); do [ -e ${resume} ] && break; sleep 0.1; done`,
    '-ex', 'delete', '-ex', 'detach'], { stdio: ['ignore', 'pipe', 'pipe'] });
  gdb.stdout.on('data', (d) => { output += d; });
  gdb.stderr.on('data', (d) => { output += d; });
  const exited = new Promise((resolve) => gdb.on('exit', (code) => resolve(code)));
  await until('gdb stopping at the control step', () => existsSync(halted), 60_000);
  assert.match(output, /Breakpoint 1, .*control_step/, `gdb stopped at the breakpoint:\n${output}`);
  await until('the page saying the car is halted by the debugger', async () => (await bar.textContent()).startsWith('Halted by the debugger: cruise (GDB from 127.0.0.1:'), 5_000);
  await page.screenshot({ path: join(shots, 'debugger-halted.png') });
  t.ok(`gdb-multiarch stopped cruise at its control step; the page: "${(await bar.textContent()).slice(0, 60)}…"`);

  const frozen = (await state()).t;
  await sleep(2_000);
  const still = await state();
  assert.equal(still.t, frozen, 'the bus time stands still while the debugger holds the car');
  t.ok(`the bus time stood at ${frozen.toFixed(3)} s for 2 s of the halt`);

  const refused = await fetch(`${base}/api/recording`, {
    method: 'POST',
    headers: { authorization: `Bearer ${token}`, 'content-type': 'application/json' },
    body: JSON.stringify({ on: true }),
  });
  assert.equal(refused.status, 409, 'an action while the car is halted');
  const reason = (await refused.json()).error;
  assert.match(reason, /halted by the debugger \(cruise\)/);
  t.ok(`an action while halted is refused at once: "${reason}"`);

  writeFileSync(resume, '');
  const code = await exited;
  gdb = null;
  assert.equal(code, 0, `gdb-multiarch's exit status:\n${output}`);
  assert.match(output, /Inferior 1 .* detached/, `gdb detached:\n${output}`);
  await until('the page saying the server waits again', async () => (await bar.textContent()).startsWith(`cruise: GDB server on ${gdbAddr}`), 5_000);
  t.ok('gdb detached; the page names the waiting server again');

  // The pause lasted over 2 s: a car catching up on it would run that far ahead at once.
  const resumed = (await state()).t;
  await sleep(2_000);
  const after = await state();
  const advance = after.t - resumed;
  assert.ok(advance > 0.05 && advance < 2.0 * 1.6, `the car runs on at its pace after the detach (advanced ${advance.toFixed(2)} s in 2 s)`);
  t.ok(`the car runs on at its pace: ${advance.toFixed(2)} s of bus time in 2 s after the detach`);

  assert.deepEqual(verdicts(after), before, 'no verdict changed over the pause');
  t.ok(`no verdict changed over the pause (${Object.entries(before).map(([e, v]) => `${e} ${v}`).join(', ')})`);
  assert.deepEqual(t.problems, [], 'the page logged no errors');
});
if (gdb) gdb.kill();
rmSync(work, { recursive: true, force: true });
