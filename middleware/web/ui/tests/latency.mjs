// The dashboard's benchmark, in Debian's Chromium: the bytes the page transfers on its
// first load, and the latency from a frame on the bus to its update in the browser.
//
// The frames are put on the virtual car's bus through its socketcand server (as any tool
// on the bus would), with an identifier outside the catalogue; the gateway reads the bus
// over socketcand, and the page's Bus view counts the unknown frames. The latency is from
// just before the frame is written to the socket to the moment the page's counter changes
// (both clocks are this machine's: performance.timeOrigin + performance.now()).
//
// node tests/latency.mjs BASE_URL SOCKETCAND_HOST:PORT [FRAMES]

import net from 'node:net';
import { launchChromium } from './harness.mjs';

const [base, socketcand, framesArg] = process.argv.slice(2);
const frames = Number(framesArg ?? 200);
const [host, port] = socketcand.split(':');
const now = () => performance.timeOrigin + performance.now();

const browser = await launchChromium();
const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
let firstLoad = 0;
const files = [];
page.on('response', async (response) => {
  try {
    const body = await response.body();
    firstLoad += body.length;
    files.push(`${new URL(response.url()).pathname} ${body.length}`);
  } catch {
    // A WebSocket upgrade has no body.
  }
});
await page.goto(`${base}/bus`, { waitUntil: 'networkidle' });
await page.waitForSelector('[data-testid=unknown-frames]');
console.log(`first load: ${firstLoad} bytes in ${files.length} responses (${files.join(', ')})`);

// The page notes when the counter changes.
await page.evaluate(() => {
  const el = document.querySelector('[data-testid=unknown-frames]');
  window.__changes = [];
  new MutationObserver(() => window.__changes.push([performance.timeOrigin + performance.now(), el.textContent])).observe(el, { childList: true, characterData: true, subtree: true });
});

// A socketcand client on the car's bus.
const socket = net.connect(Number(port), host);
let inbox = '';
socket.on('data', (d) => { inbox += d.toString(); if (inbox.length > 1 << 16) inbox = inbox.slice(-4096); });
const waitFor = async (text) => {
  for (let i = 0; i < 100 && !inbox.includes(text); i++) await new Promise((r) => setTimeout(r, 20));
  if (!inbox.includes(text)) throw new Error(`socketcand: no '${text}'`);
  inbox = '';
};
await waitFor('< hi >');
socket.write('< open can0 >');
await waitFor('< ok >');
socket.write('< rawmode >');
await waitFor('< ok >');
await new Promise((r) => setTimeout(r, 500));

const latencies = [];
for (let i = 0; i < frames; i++) {
  const before = await page.evaluate(() => window.__changes.length);
  const sent = now();
  socket.write(`< send 123 1 ${(i & 0xff).toString(16).padStart(2, '0')} >`);
  let seen = null;
  for (let k = 0; k < 200 && seen === null; k++) {
    await new Promise((r) => setTimeout(r, 2));
    seen = await page.evaluate((n) => (window.__changes.length > n ? window.__changes[n][0] : null), before);
  }
  if (seen !== null) latencies.push(seen - sent);
  // Apart by more than the stream's 50 ms, at an irregular phase.
  await new Promise((r) => setTimeout(r, 120 + Math.random() * 80));
}
socket.destroy();
await browser.close();
latencies.sort((a, b) => a - b);
const at = (q) => latencies[Math.min(latencies.length - 1, Math.floor(q * latencies.length))];
console.log(`frame on the bus -> browser: ${latencies.length} of ${frames} frames seen; min ${latencies[0].toFixed(1)} ms, median ${at(0.5).toFixed(1)} ms, p95 ${at(0.95).toFixed(1)} ms, max ${latencies[latencies.length - 1].toFixed(1)} ms`);
if (latencies.length < frames) process.exit(1);
