// What the browser tests share: Debian's Chromium started headless as the project's machines
// run it (never a downloaded browser), numbered steps printed as they pass, the pages'
// console errors collected, and waiting for a condition with a deadline.

import { chromium } from 'playwright-core';

/** Debian's Chromium, headless, without the background traffic of a desktop browser. */
export function launchChromium() {
  return chromium.launch({
    executablePath: '/usr/bin/chromium',
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
}

/**
 * A test's steps and the pages' errors: `ok(what)` prints a passed step with its time,
 * `watch(page)` collects the page's console errors into `problems`, and `run(body)` runs
 * the steps, failing on the first that throws and closing the browser either way.
 */
export function steps(browser) {
  const problems = [];
  const started = Date.now();
  let step = 0;
  return {
    problems,
    /** How many steps passed. */
    count: () => step,
    ok(what) {
      step += 1;
      console.log(`ok ${step} - ${what} [${((Date.now() - started) / 1000).toFixed(1)} s]`);
    },
    watch(page) {
      page.on('console', (m) => {
        if (m.type() === 'error') problems.push(`console error: ${m.text()}`);
      });
      page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
    },
    async run(body) {
      try {
        await body();
      } catch (error) {
        console.error(`not ok ${step + 1} - ${error.message}`);
        if (problems.length) console.error(problems.join('\n'));
        await browser.close();
        process.exit(1);
      }
      await browser.close();
    },
  };
}

/** Polls `check` every 100 ms until it gives a truthy value (returned), or throws after `timeoutMs`. */
export async function until(what, check, timeoutMs) {
  const deadline = Date.now() + timeoutMs;
  for (;;) {
    const value = await check();
    if (value) return value;
    if (Date.now() > deadline) throw new Error(`timed out after ${timeoutMs / 1000} s waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 100));
  }
}
