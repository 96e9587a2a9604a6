// Measures the phone app on a 3 × 12 MP fish-eye bracket (made by `skydome synth`) in headless
// Chromium: the time in the core (worker), the wall time from picking the photos to the
// preview, the tab's peak memory (renderer process resident set, sampled every 100 ms; the
// worker runs in the same process), the wasm linear memory's high-water mark, and the native
// CLI's time for the same frames and options (and its stage times). Also the gzipped .wasm size.
//   node measure.mjs [--size 3464] [--evs -2,0,2] [--threads N] [--out results.json] [--again] [--idle MS] [--reserve MiB]
// --again merges the same photos a second time in the same page (`again` in the output).
// --evs gives the frames' exposure values (`skydome synth --evs`): -4,-3,-2,-1,0,1,2,3,4 is a
// phone's 9-frame bracket.
// --threads N loads the page with ?threads=N: the threaded core with a pool of N workers (the
// page is cross-origin isolated by `skydome serve`), 0 the single-threaded core; without it the
// app picks (one thread per core).
// --memory MiB loads the page with ?memory=MiB: the budget for the photos decoded at once (the
// app's default 256 MiB; `none`, no limit); above it the core reads them one at a time
// (`streamed` in the output).
// Speed is measured here, never asserted in tests.
import { execFileSync, spawnSync } from 'node:child_process';
import { existsSync, readFileSync, readdirSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { gzipSync } from 'node:zlib';
import {
  appDir, onScreen, phone, resultOrError, serve, setSettings, tempDir,
} from './tests/support.mjs';

const arg = (name, dflt) => {
  const i = process.argv.indexOf(name);
  return i > 0 ? process.argv[i + 1] : dflt;
};
const size = Number(arg('--size', '3464')); // 3464² = 12.0 MP
const outFile = arg('--out', null);
const threads = arg('--threads', null);
const evs = arg('--evs', '-2,0,2');
const memory = arg('--memory', null);
// --reserve MiB loads the page with ?reserve=MiB: the memory the core reserves while idle for
// the first merge (the app's default: 160 MiB; 0: none, as before this existed).
const reserve = arg('--reserve', null);
// --idle MS: how long the app sits loaded before the photos are picked (default 1000 ms).
const idleMs = Number(arg('--idle', '1000'));

/** Memory of this test's Chromium renderer processes (command lines carry the fresh profile's
 *  folder, so other Chromium instances on the machine are not counted): for each, the resident
 *  set (VmRSS, which also counts the shared Chromium binary and the camera's shared frames)
 *  and its own memory (RssAnon + RssShmem: heaps, the wasm memory, frame buffers; like
 *  Chrome's task manager's footprint, without the shared binary). The tab is the renderer
 *  with the most; its worker runs in the same process. */
function renderers(profile) {
  const out = new Map();
  for (const pid of readdirSync('/proc').filter((d) => /^\d+$/.test(d))) {
    try {
      const cmd = readFileSync(`/proc/${pid}/cmdline`, 'latin1');
      if (!cmd.includes('--type=renderer') || !cmd.includes(profile)) continue;
      const st = readFileSync(`/proc/${pid}/status`, 'latin1');
      const kb = (k) => Number((st.match(new RegExp(`${k}:\\s+(\\d+) kB`)) || [0, 0])[1]) * 1024;
      out.set(pid, { rss: kb('VmRSS'), anon: kb('RssAnon') + kb('RssShmem'), shmem: kb('RssShmem') });
    } catch { /* process ended */ }
  }
  return out;
}

/** CPU time (s, {user, sys}, all threads: the page, the workers, V8's compiler threads) of
 *  this test's Chromium renderer processes so far (system time is mostly the kernel backing
 *  fresh pages). Under load, CPU time says more than wall
 *  time about what a merge costs (10 ms resolution). */
function rendererCpu(profile) {
  let user = 0;
  let sys = 0;
  for (const pid of readdirSync('/proc').filter((d) => /^\d+$/.test(d))) {
    try {
      const cmd = readFileSync(`/proc/${pid}/cmdline`, 'latin1');
      if (!cmd.includes('--type=renderer') || !cmd.includes(profile)) continue;
      // Fields after the command's closing parenthesis: utime and stime are the 12th and 13th.
      const f = readFileSync(`/proc/${pid}/stat`, 'latin1').split(') ')[1].split(' ');
      user += Number(f[11]);
      sys += Number(f[12]);
    } catch { /* process ended */ }
  }
  return { user: user / 100, sys: sys / 100 }; // USER_HZ
}

const peaks = new Map();
// The tab's resident set over the merge (ms since the photos were picked, MB), to see which step
// makes the peak.
const timeline = [];
let t0 = null;
function sample(profile) {
  const now = renderers(profile);
  if (t0 != null && now.size) {
    const top = Math.max(...[...now.values()].map((m) => m.rss));
    timeline.push([Math.round(performance.now() - t0), Math.round(top / 2 ** 20)]);
  }
  for (const [pid, m] of now) {
    const p = peaks.get(pid) || { rss: 0, anon: 0, shmem: 0 };
    peaks.set(pid, { rss: Math.max(p.rss, m.rss), anon: Math.max(p.anon, m.anon), shmem: Math.max(p.shmem, m.shmem) });
  }
}
function tabPeak() {
  return [...peaks.values()].reduce((a, b) => (b.rss > a.rss ? b : a), { rss: 0, anon: 0 });
}

// The native side of the comparison is the optimised build (a debug CLI would flatter the
// browser): $SKYDOME_BIN, else target/release/skydome.
const cliBin = process.env.SKYDOME_BIN
  || path.join(path.dirname(fileURLToPath(import.meta.url)), '..', 'target', 'release', 'skydome');
if (!existsSync(cliBin)) throw new Error(`${cliBin} is missing: run cargo build --release -p skydome-cli`);
const dir = tempDir('measure');
console.error(`synthesising a ${size}² bracket in ${dir}`);
execFileSync(cliBin, ['synth', '-o', dir, '--size', String(size), `--evs=${evs}`, '--quiet']);
const frames = readdirSync(dir).filter((f) => /^frame_\d+\.jpg$/.test(f)).sort().map((f) => path.join(dir, f));

const cliArgs = ['merge', ...frames, '--times-file', path.join(dir, 'times.txt'), '--fisheye',
  '--lens-model', 'stereographic', '--fov', '235', '--crop', '--north', '0', '--sun', 'auto',
  '--preview', path.join(dir, 'cli.jpg'), '-o', path.join(dir, 'cli.hdr'), '--quiet', '--force'];
// SKYDOME_TIMINGS=1: the CLI prints its own stage times on stderr (`timings: decoding 0.123 s,
// …, writing 0.045 s`), compared stage by stage with the browser's.
const c0 = performance.now();
const cliRun = spawnSync(cliBin, cliArgs, { env: { ...process.env, SKYDOME_TIMINGS: '1' }, encoding: 'utf8' });
const cliMs = performance.now() - c0;
if (cliRun.status !== 0) throw new Error(`skydome merge failed: ${cliRun.stderr}`);
const cliStages = Object.fromEntries([...(cliRun.stderr.match(/^timings: (.*)$/m) || [null, ''])[1]
  .matchAll(/(\w+) ([\d.]+) s/g)].map((m) => [m[1], Number(m[2])]));

const server = await serve();
const p = await phone(server.origin);
const sampler = setInterval(() => sample(p.profile), 100);
try {
  // The gallery path alone: no camera (its frame buffers and the live lens detection are not
  // part of a merge; the app stops the camera while merging anyway).
  await p.page.addInitScript(() => {
    navigator.mediaDevices.getUserMedia = () => Promise.reject(new DOMException('measuring without a camera', 'NotAllowedError'));
  });
  const query = new URLSearchParams();
  if (threads != null) query.set('threads', threads);
  if (memory != null) query.set('memory', memory);
  if (reserve != null) query.set('reserve', reserve);
  await p.page.goto(`${server.origin}/${query.size ? `?${query}` : ''}`);
  await onScreen(p.page, 'camera');
  await p.page.waitForFunction(() => document.body.dataset.core);
  await setSettings(p.page, { fisheye: true, sun: 'auto', north: '0', equirect: false });
  await p.page.waitForTimeout(idleMs);
  sample(p.profile);
  const baseline = tabPeak();
  peaks.clear();
  const cdp = await p.context.newCDPSession(p.page);
  await cdp.send('Performance.enable');
  const since = await p.page.evaluate(() => Date.now());
  const w0 = performance.now();
  t0 = w0;
  const cpu0 = rendererCpu(p.profile);
  await p.page.setInputFiles('#gallery', [...frames, path.join(dir, 'times.txt')]);
  const msg = await resultOrError(p.page, since);
  const wallMs = performance.now() - w0;
  const cpu1 = rendererCpu(p.profile);
  // The preview on screen (decoded by the page) is part of the tab's memory.
  await p.page.waitForFunction(() => document.getElementById('preview').complete);
  await p.page.waitForTimeout(1000);
  if (msg) throw new Error(msg);
  sample(p.profile);
  const peak = tabPeak();
  const metrics = Object.fromEntries((await cdp.send('Performance.getMetrics')).metrics.map((m) => [m.name, m.value]));
  const core = await p.page.evaluate(() => window.__skydomeCoreMs);
  const stages = await p.page.evaluate(() => window.__skydomeStageMs);
  const stageMemory = await p.page.evaluate(() => window.__skydomeStageMemory);
  const wasm = await p.page.evaluate(() => window.__skydomeAsk('memory'));
  const coreInfo = await p.page.evaluate(() => window.__skydomeCore);
  const streamed = await p.page.evaluate(() => window.__skydomeStreamed);
  // The idle warm-up's steps (ms each), when the app reports them.
  const warmUp = await p.page.evaluate(() => window.__skydomeAsk('warmUp')).catch(() => null);
  // --again: the same photos picked a second time in the same page (the core's code compiled
  // and its memory touched by the first merge).
  let again = null;
  if (process.argv.includes('--again')) {
    await p.page.waitForTimeout(1000);
    const since2 = await p.page.evaluate(() => Date.now());
    const cpu2 = rendererCpu(p.profile);
    await p.page.setInputFiles('#gallery', [...frames, path.join(dir, 'times.txt')]);
    const msg2 = await resultOrError(p.page, since2);
    const cpu3 = rendererCpu(p.profile);
    if (msg2) throw new Error(msg2);
    const stages2 = await p.page.evaluate(() => window.__skydomeStageMs);
    again = {
      browser_core_s: (await p.page.evaluate(() => window.__skydomeCoreMs)) / 1000,
      tab_cpu_s: cpu3.user + cpu3.sys - cpu2.user - cpu2.sys,
      tab_cpu_sys_s: cpu3.sys - cpu2.sys,
      browser_stage_s: Object.fromEntries(Object.entries(stages2).map(([k, v]) => [k, v / 1000])),
    };
  }
  // The .wasm the page loaded.
  const wasmFile = path.join(appDir, coreInfo && coreInfo.build === 'threaded' ? 'pkg-mt' : 'pkg', 'skydome_web_bg.wasm');
  const gz = gzipSync(readFileSync(wasmFile), { level: 9 }).length;
  const raw = readFileSync(wasmFile).length;
  const result = {
    core: coreInfo,
    streamed,
    frames: frames.length,
    megapixels_each: (size * size) / 1e6,
    browser_core_s: core / 1000,
    browser_wall_s: wallMs / 1000,
    // CPU time of the tab (all its threads) from the pick to the result on screen.
    tab_cpu_s: cpu1.user + cpu1.sys - cpu0.user - cpu0.sys,
    tab_cpu_sys_s: cpu1.sys - cpu0.sys,
    browser_stage_s: Object.fromEntries(Object.entries(stages).map(([k, v]) => [k, v / 1000])),
    cli_s: cliMs / 1000,
    cli_stage_s: cliStages,
    cli_binary: cliBin,
    tab_peak_rss_mb: peak.rss / 2 ** 20,
    tab_peak_own_mb: peak.anon / 2 ** 20,
    tab_peak_shmem_mb: peak.shmem / 2 ** 20,
    tab_before_rss_mb: baseline.rss / 2 ** 20,
    tab_before_own_mb: baseline.anon / 2 ** 20,
    wasm_memory_high_water_mb: wasm.wasmBytes / 2 ** 20,
    wasm_memory_after_stage_mb: Object.fromEntries(Object.entries(stageMemory || {}).map(([k, v]) => [k, v / 2 ** 20])),
    page_js_heap_used_mb: metrics.JSHeapUsedSize / 2 ** 20,
    tab_rss_timeline_ms_mb: timeline,
    wasm_bytes: raw,
    wasm_gzip_bytes: gz,
    ...(again ? { again } : {}),
    ...(warmUp ? { warm_up_ms: warmUp.ms } : {}),
  };
  console.log(JSON.stringify(result, null, 2));
  if (outFile) writeFileSync(outFile, JSON.stringify(result, null, 2));
} finally {
  clearInterval(sampler);
  await p.close();
  server.stop();
}
