// Times one JPEG decode per call in headless Chromium for two builds of decode-bench (e.g.
// main's and a branch's zune-jpeg), loaded in the same page and alternated, with the decoded
// pixels' digests compared. Optionally records Chromium's CPU profile (CDP Profiler).
//   node run.mjs A.wasm B.wasm|- ROUNDS FILE.jpg... [--prof OUT.cpuprofile]
// Prints per build the median and all times (ms), the median of the paired ratios B/A (each
// frame decoded by A and B back to back, so load drifts cancel), and whether the digests
// match. Speed is measured here, never asserted in tests.
// The same wasm also compares zune-jpeg's wasm colour conversion with its scalar code on every
// in-range input and 2 M random calls (prints 0 when bit-identical):
//   node -e "WebAssembly.instantiate(require('fs').readFileSync('X.wasm')).then(({instance}) =>
//     console.log(instance.exports.colour_mismatches(2000000)))"
import { chromium } from 'playwright-core';
import fs from 'node:fs';
import path from 'node:path';

const args = process.argv.slice(2);
let prof = null;
const pi = args.indexOf('--prof');
if (pi >= 0) [, prof] = args.splice(pi, 2);
const [wa, wb, roundsArg, ...files] = args;
const rounds = Number(roundsArg);
const keys = wb === '-' ? ['A'] : ['A', 'B'];
const wasm = { A: fs.readFileSync(wa), B: wb === '-' ? null : fs.readFileSync(wb) };

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium', headless: true,
  args: ['--no-sandbox', '--disable-gpu'],
});
const page = await browser.newPage();
await page.route('http://bench.invalid/**', (r) => {
  const name = decodeURIComponent(new URL(r.request().url()).pathname.slice(1));
  if (name === 'index.html') return r.fulfill({ body: '<!doctype html><title>bench</title>', contentType: 'text/html' });
  if (name === 'A.wasm' || name === 'B.wasm') return r.fulfill({ body: wasm[name[0]], contentType: 'application/wasm' });
  return r.fulfill({ body: fs.readFileSync(files[Number(name)]), contentType: 'image/jpeg' });
});
await page.goto('http://bench.invalid/index.html');
await page.evaluate(async ([keys, n]) => {
  window.mods = {};
  for (const k of keys) {
    const { instance } = await WebAssembly.instantiateStreaming(fetch(`/${k}.wasm`), {});
    window.mods[k] = instance.exports;
  }
  window.data = [];
  for (let i = 0; i < n; i++) window.data.push(new Uint8Array(await (await fetch(`/${i}`)).arrayBuffer()));
}, [keys, files.length]);

const decodeOnce = (k, fi) => page.evaluate(([k, fi]) => {
  const m = window.mods[k];
  const d = window.data[fi];
  const at = m.input_buf(d.length); // may grow the memory: take its buffer after
  new Uint8Array(m.memory.buffer, at, d.length).set(d);
  const t0 = performance.now();
  const n = m.decode();
  const ms = performance.now() - t0;
  const digest = `${n}:${(m.hash(1) >>> 0).toString(16)}${(m.hash(0) >>> 0).toString(16).padStart(8, '0')}`;
  m.release();
  return [ms, digest];
}, [k, fi]);

const digests = { A: [], B: [] };
// One decode of each file first, so that both builds run optimised code when timed.
for (const k of keys) for (let fi = 0; fi < files.length; fi++) digests[k].push((await decodeOnce(k, fi))[1]);
let cdp = null;
if (prof) {
  cdp = await page.context().newCDPSession(page);
  await cdp.send('Profiler.enable');
  await cdp.send('Profiler.setSamplingInterval', { interval: 100 });
  await cdp.send('Profiler.start');
}
const ms = { A: [], B: [] };
const ratios = [];
for (let r = 0; r < rounds; r++) {
  for (let fi = 0; fi < files.length; fi++) {
    const t = {};
    for (const k of (r + fi) % 2 ? [...keys].reverse() : keys) {
      const [m, digest] = await decodeOnce(k, fi);
      if (digest !== digests[k][fi]) throw new Error(`${k}: ${files[fi]} decoded differently twice`);
      ms[k].push(m);
      t[k] = m;
    }
    if (t.B !== undefined) ratios.push(t.B / t.A);
  }
}
if (cdp) {
  const { profile } = await cdp.send('Profiler.stop');
  fs.writeFileSync(prof, JSON.stringify(profile));
  // Self time per function, the top 12 (wasm functions carry their Rust symbol names).
  const byId = new Map(profile.nodes.map((n) => [n.id, n.callFrame.functionName || '(anonymous)']));
  const self = new Map();
  for (const id of profile.samples) self.set(byId.get(id), (self.get(byId.get(id)) || 0) + 1);
  const rows = [...self].sort((a, b) => b[1] - a[1]).slice(0, 12);
  for (const [name, n] of rows) console.log(`${(100 * n / profile.samples.length).toFixed(1).padStart(5)} %  ${name.slice(0, 120)}`);
}
await browser.close();

const median = (a) => { const s = [...a].sort((x, y) => x - y); return s.length % 2 ? s[s.length >> 1] : (s[s.length / 2 - 1] + s[s.length / 2]) / 2; };
for (const k of keys) {
  console.log(`${k} (${path.basename(k === 'A' ? wa : wb)}): median ${median(ms[k]).toFixed(1)} ms; all ${ms[k].map((x) => x.toFixed(0)).join(' ')}`);
}
if (keys.length === 2) {
  console.log(`B/A paired: median ${median(ratios).toFixed(3)} over ${ratios.length} pairs; B faster in ${ratios.filter((x) => x < 1).length}`);
  const same = digests.A.every((d, i) => d === digests.B[i]);
  console.log(same ? 'digests: A and B decode every file to the same bytes' : `digests DIFFER: A ${digests.A} B ${digests.B}`);
  if (!same) process.exitCode = 1;
}
