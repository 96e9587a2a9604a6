// Shared test support: the built app served by `skydome serve`, Debian's Chromium driven by
// playwright-core with a phone viewport and touch, a fresh profile per test, and a watch on
// every request the page makes (none may leave the app's origin).
import { spawn, execFileSync } from 'node:child_process';
import { existsSync, mkdtempSync, mkdirSync, rmSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = path.dirname(fileURLToPath(import.meta.url));
export const root = path.resolve(here, '../..');
export const appDir = process.env.SKYDOME_APP_DIR || path.join(root, 'target/skydome-web/app');
export const sharedData = path.resolve(root, '../shared/data');
export const shotsDir = path.join(root, 'target/skydome-web/screenshots');

/** The skydome binary: $SKYDOME_BIN, else the newest of target/{release,debug}/skydome. */
export function skydomeBin() {
  if (process.env.SKYDOME_BIN) return process.env.SKYDOME_BIN;
  const found = ['release', 'debug']
    .map((p) => path.join(root, 'target', p, 'skydome'))
    .filter((p) => existsSync(p))
    .sort((a, b) => statSync(b).mtimeMs - statSync(a).mtimeMs);
  if (found.length === 0) throw new Error('no skydome binary: run cargo build -p skydome-cli first');
  return found[0];
}

/** Runs the CLI; returns stdout. */
export function cli(args) {
  return execFileSync(skydomeBin(), args, { encoding: 'utf8', stdio: ['ignore', 'pipe', 'pipe'] });
}

/** Runs the CLI where it must fail; returns the first line of its error output. */
export function cliError(args, cwd) {
  try {
    execFileSync(skydomeBin(), args, { cwd, encoding: 'utf8', stdio: ['ignore', 'pipe', 'pipe'] });
  } catch (e) {
    return String(e.stderr).split('\n').find((l) => l.startsWith('error: ')) || String(e.stderr);
  }
  throw new Error(`skydome ${args.join(' ')} succeeded; it was expected to fail`);
}

export function tempDir(name) {
  return mkdtempSync(path.join(tmpdir(), `skydome-web-${name}-`));
}

/** Starts `skydome serve` of `dir` (the built app) on a free port; resolves to {origin, stop}.
 *  `isolation: false` serves without the COOP/COEP headers (`--no-isolation`), as a host that
 *  cannot set headers. */
export async function serve(dir = appDir, { isolation = true } = {}) {
  if (!existsSync(path.join(dir, 'index.html'))) {
    throw new Error(`${dir}: the app is not built; run crates/skydome-web/build.sh`);
  }
  const port = 18000 + Math.floor(Math.random() * 2000);
  const args = ['serve', '--addr', `127.0.0.1:${port}`, '--dir', dir, ...(isolation ? [] : ['--no-isolation'])];
  const proc = spawn(skydomeBin(), args, {
    stdio: ['ignore', 'pipe', 'pipe'],
  });
  await new Promise((resolve, reject) => {
    let out = '';
    const timer = setTimeout(() => reject(new Error(`skydome serve did not start: ${out}`)), 15000);
    proc.stdout.on('data', (d) => { out += d; if (out.includes('serving')) { clearTimeout(timer); resolve(); } });
    proc.stderr.on('data', (d) => { out += d; });
    proc.on('exit', (code) => { clearTimeout(timer); reject(new Error(`skydome serve exited ${code}: ${out}`)); });
  });
  return {
    origin: `http://127.0.0.1:${port}`,
    stop: () => { proc.kill('SIGTERM'); },
  };
}

export const CHROMIUM_FLAGS = [
  '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--use-fake-device-for-media-stream', '--use-fake-ui-for-media-stream',
  // Extra flags for measuring (e.g. SKYDOME_CHROMIUM_FLAGS='--js-flags=--no-liftoff'), split on spaces.
  ...(process.env.SKYDOME_CHROMIUM_FLAGS || '').split(' ').filter(Boolean),
];

/** A phone: Chromium with a fresh profile, 412 × 915 CSS px portrait (or `viewport`), touch,
 *  the camera allowed, service workers allowed (`serviceWorkers: 'block'` blocks them). Every
 *  request is recorded in `requests`. */
export async function phone(origin, { downloads = true, viewport = { width: 412, height: 915 }, serviceWorkers = 'allow' } = {}) {
  const profile = tempDir('profile');
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: CHROMIUM_FLAGS,
    viewport,
    deviceScaleFactor: 2,
    isMobile: true,
    hasTouch: true,
    acceptDownloads: downloads,
    // The orientation sensors need these for deviceorientationabsolute events to carry values.
    permissions: ['camera', 'accelerometer', 'gyroscope', 'magnetometer'],
    serviceWorkers,
  });
  const requests = [];
  context.on('request', (r) => requests.push(r.url()));
  const page = context.pages()[0] || (await context.newPage());
  // One step (a page load, a merge) over two minutes is a hang: fail there, naming the step,
  // well before the whole file's time limit (package.json) cuts every test short.
  page.setDefaultTimeout(Number(process.env.SKYDOME_WEB_STEP_MS || 120000));
  if (process.env.SKYDOME_WEB_DEBUG) {
    page.on('console', (m) => console.log('[console]', m.text()));
    context.on('requestfailed', (r) => console.log('[failed]', r.url(), r.failure() && r.failure().errorText));
  }
  const errors = [];
  page.on('pageerror', (e) => errors.push(String(e)));
  return {
    context,
    page,
    profile,
    requests,
    errors,
    /** URLs that left `origin` (data: and blob: URLs stay in the page). */
    foreign: () => requests.filter((u) => !u.startsWith(`${origin}/`) && !/^(data|blob):/.test(u)),
    close: async () => { await context.close(); rmSync(profile, { recursive: true, force: true }); },
  };
}

/** Saves a screenshot of the page under target/skydome-web/screenshots. */
export async function screenshot(page, name) {
  mkdirSync(shotsDir, { recursive: true });
  const file = path.join(shotsDir, `${name}.png`);
  await page.screenshot({ path: file, fullPage: false });
  return file;
}

/** Waits until the app shows `screen` ('camera', 'work', 'result', 'settings'). */
export async function onScreen(page, screen) {
  await page.waitForFunction((s) => document.body.dataset.screen === s, screen);
}

/** Waits for a fresh result (after `since`, a Date.now() of the page) or an error message. */
export async function resultOrError(page, since) {
  await page.waitForFunction((t) => Number(document.body.dataset.ready || 0) > t
    || (!document.getElementById('message').hidden && document.getElementById('message').className !== 'info'), since);
  const msg = await page.$eval('#message', (m) => (m.hidden ? null : m.textContent));
  return msg;
}

/** Sets settings through the Settings screen, like a user. */
export async function setSettings(page, values) {
  await page.click('#to-settings');
  await onScreen(page, 'settings');
  for (const [name, v] of Object.entries(values)) {
    const sel = `#settings-form [name="${name}"]`;
    if (typeof v === 'boolean') await page.setChecked(sel, v);
    else if ((await page.$eval(sel, (e) => e.tagName)) === 'SELECT') await page.selectOption(sel, String(v));
    else await page.fill(sel, String(v));
  }
  await page.$eval('#settings-form', (f) => f.dispatchEvent(new Event('change')));
  await page.click('#settings-done');
  await onScreen(page, 'camera');
}

/** Clicks a save button and returns the downloaded file's bytes and name. */
export async function download(page, button) {
  const [dl] = await Promise.all([page.waitForEvent('download'), page.click(button)]);
  const file = await dl.path();
  const { readFileSync } = await import('node:fs');
  return { name: dl.suggestedFilename(), bytes: readFileSync(file) };
}

/** The header lines of a Radiance file (up to the blank line). */
export function headerLines(bytes) {
  const text = bytes.subarray(0, Math.min(bytes.length, 4096)).toString('latin1');
  return text.slice(0, text.indexOf('\n\n')).split('\n');
}
