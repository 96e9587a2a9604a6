// Measures the phone app on a 3 × 12 MP fish-eye bracket (made by `skydome synth`) in headless
// Chromium: the time in the core (worker), the wall time from picking the photos to the
// preview, the tab's peak memory (renderer process resident set, sampled every 100 ms; the
// worker runs in the same process), the wasm linear memory's high-water mark, and the native
// CLI's time for the same frames and options. Also the gzipped .wasm size.
//   node measure.mjs [--size 3464] [--out results.json]
// Speed is measured here, never asserted in tests.
import { execFileSync } from 'node:child_process';
import { readFileSync, readdirSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import { gzipSync } from 'node:zlib';
import {
  appDir, onScreen, phone, resultOrError, serve, setSettings, skydomeBin, tempDir,
} from './tests/support.mjs';

const arg = (name, dflt) => {
  const i = process.argv.indexOf(name);
  return i > 0 ? process.argv[i + 1] : dflt;
};
const size = Number(arg('--size', '3464')); // 3464² = 12.0 MP
const outFile = arg('--out', null);

function rendererRss() {
  // Sum of the resident sets of Chromium's renderer processes (one tab is open).
  let total = 0;
  for (const pid of readdirSync('/proc').filter((d) => /^\d+$/.test(d))) {
    try {
      const cmd = readFileSync(`/proc/${pid}/cmdline`, 'latin1');
      if (!cmd.includes('chromium') || !cmd.includes('--type=renderer')) continue;
      const status = readFileSync(`/proc/${pid}/status`, 'latin1');
      const m = status.match(/VmRSS:\s+(\d+) kB/);
      if (m) total += Number(m[1]) * 1024;
    } catch { /* process ended */ }
  }
  return total;
}

const dir = tempDir('measure');
console.error(`synthesising a ${size}² bracket in ${dir}`);
execFileSync(skydomeBin(), ['synth', '-o', dir, '--size', String(size), '--quiet']);
const frames = readdirSync(dir).filter((f) => /^frame_\d+\.jpg$/.test(f)).sort().map((f) => path.join(dir, f));

const cliArgs = ['merge', ...frames, '--times-file', path.join(dir, 'times.txt'), '--fisheye',
  '--lens-model', 'stereographic', '--fov', '235', '--crop', '--north', '0', '--sun', 'auto',
  '--preview', path.join(dir, 'cli.jpg'), '-o', path.join(dir, 'cli.hdr'), '--quiet', '--force'];
const c0 = performance.now();
execFileSync(skydomeBin(), cliArgs);
const cliMs = performance.now() - c0;

const server = await serve();
const p = await phone(server.origin);
let peak = 0;
const sampler = setInterval(() => { peak = Math.max(peak, rendererRss()); }, 100);
try {
  await p.page.goto(`${server.origin}/`);
  await onScreen(p.page, 'camera');
  await setSettings(p.page, { fisheye: true, sun: 'auto', north: '0', equirect: false });
  const baseline = rendererRss();
  const cdp = await p.context.newCDPSession(p.page);
  await cdp.send('Performance.enable');
  const since = await p.page.evaluate(() => Date.now());
  const w0 = performance.now();
  await p.page.setInputFiles('#gallery', [...frames, path.join(dir, 'times.txt')]);
  const msg = await resultOrError(p.page, since);
  const wallMs = performance.now() - w0;
  if (msg) throw new Error(msg);
  peak = Math.max(peak, rendererRss());
  const metrics = Object.fromEntries((await cdp.send('Performance.getMetrics')).metrics.map((m) => [m.name, m.value]));
  const core = await p.page.evaluate(() => window.__skydomeCoreMs);
  const wasm = await p.page.evaluate(() => window.__skydomeAsk('memory'));
  const gz = gzipSync(readFileSync(path.join(appDir, 'pkg/skydome_web_bg.wasm')), { level: 9 }).length;
  const raw = readFileSync(path.join(appDir, 'pkg/skydome_web_bg.wasm')).length;
  const result = {
    frames: frames.length,
    megapixels_each: (size * size) / 1e6,
    browser_core_s: core / 1000,
    browser_wall_s: wallMs / 1000,
    cli_s: cliMs / 1000,
    cli_binary: skydomeBin(),
    tab_peak_rss_mb: peak / 2 ** 20,
    tab_rss_before_mb: baseline / 2 ** 20,
    wasm_memory_high_water_mb: wasm.wasmBytes / 2 ** 20,
    page_js_heap_used_mb: metrics.JSHeapUsedSize / 2 ** 20,
    wasm_bytes: raw,
    wasm_gzip_bytes: gz,
  };
  console.log(JSON.stringify(result, null, 2));
  if (outFile) writeFileSync(outFile, JSON.stringify(result, null, 2));
} finally {
  clearInterval(sampler);
  await p.close();
  server.stop();
}
