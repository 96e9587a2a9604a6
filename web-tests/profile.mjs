// Where the app's first merge after loading spends its time, against the second merge of the
// same photos in the same page (3 × 12 MP synthetic bracket, as measure.mjs):
// - Chromium CPU profiles in every thread that runs JavaScript or WebAssembly: the page, the
//   core's worker, the threaded core's pool workers (nested workers of the core's worker) and
//   the decoding workers. Prints self time per function (ms), first merge against second,
//   summed over the threads and per thread kind, largest differences first; wasm functions
//   carry their Rust names (build.sh keeps the module's name section).
// - with --trace, Chromium's trace of V8's WebAssembly compiler from page load on: time spent
//   compiling, per thread and merge. Run with
//     SKYDOME_CHROMIUM_FLAGS=--js-flags=--trace-wasm-compilation-times DEBUG=pw:browser \
//       node profile.mjs --trace --no-cpu --out P 2> P.log
//   to also get each optimised (TurboFan) function's index in P.log, which
//   tools/wasm_compiles.py names by merge (which functions V8 optimised during the first merge:
//   those the warm-up did not make hot).
//   node profile.mjs [--size 3464] [--threads N] [--idle MS] [--reserve MiB] [--interval US]
//                    [--top N] [--out PREFIX] [--trace [CATEGORIES]] [--no-cpu] [--warmup N]
// --out PREFIX writes PREFIX.first.T.cpuprofile and PREFIX.second.T.cpuprofile per thread T
// (DevTools, Performance panel, loads them) and PREFIX.trace.json with --trace. CPU samples are
// taken on the JavaScript threads only: V8's background compilation shows in the trace, not
// in the profiles. PROFILE_DEBUG=1 prints the steps. Speed is measured here, never asserted in
// tests.
import { execFileSync } from 'node:child_process';
import { readdirSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import path from 'node:path';

const arg = (name, dflt) => {
  const i = process.argv.indexOf(name);
  return i > 0 ? process.argv[i + 1] : dflt;
};
const size = Number(arg('--size', '3464'));
const threads = arg('--threads', null);
const reserve = arg('--reserve', null);
// --warmup N loads the page with ?warmup=N (how many 256² merges the idle warm-up runs).
const warmup = arg('--warmup', null);
const idleMs = Number(arg('--idle', '1000'));
const interval = Number(arg('--interval', '250'));
const top = Number(arg('--top', '40'));
const outPrefix = arg('--out', null);
// --no-cpu: no CPU profiles (with --trace: the trace alone, without the profiler's own code logging).
const noCpu = process.argv.includes('--no-cpu');

// A DevTools port beside playwright's pipe: playwright cannot address the workers' sessions.
const port = 19000 + Math.floor(Math.random() * 2000);
process.env.SKYDOME_CHROMIUM_FLAGS = `${process.env.SKYDOME_CHROMIUM_FLAGS || ''} --remote-debugging-port=${port}`;
const {
  onScreen, phone, resultOrError, serve, setSettings, skydomeBin, tempDir,
} = await import('./tests/support.mjs');
// playwright-core bundles the `ws` client (Node 20 has no WebSocket of its own).
const { ws: WebSocket } = createRequire(import.meta.url)('playwright-core/lib/utilsBundle');

/** A CDP connection to the browser, flat sessions (`sessionId` on each message). */
class Cdp {
  constructor(url) {
    this.next = 1;
    this.pending = new Map();
    this.handlers = [];
    this.sock = new WebSocket(url, { perMessageDeflate: false, maxPayload: 1 << 30 });
    this.sock.on('message', (data) => {
      const m = JSON.parse(String(data));
      if (m.id && this.pending.has(m.id)) {
        const { resolve, reject, method } = this.pending.get(m.id);
        this.pending.delete(m.id);
        if (m.error) reject(new Error(`${method}: ${m.error.message}`));
        else resolve(m.result);
      } else if (m.method) {
        for (const h of this.handlers) h(m);
      }
    });
    this.open = new Promise((resolve, reject) => { this.sock.on('open', resolve); this.sock.on('error', reject); });
  }

  /** Resolves to the result; rejects on an error or after `ms` without an answer (a target
   *  that ended without a word). */
  send(method, params = {}, sessionId = undefined, ms = 30000) {
    const id = this.next++;
    this.sock.send(JSON.stringify({ id, method, params, ...(sessionId ? { sessionId } : {}) }));
    return new Promise((resolve, reject) => {
      const timer = setTimeout(() => { this.pending.delete(id); reject(new Error(`${method}: no answer`)); }, ms);
      this.pending.set(id, {
        resolve: (v) => { clearTimeout(timer); resolve(v); },
        reject: (e) => { clearTimeout(timer); reject(e); },
        method,
      });
    });
  }

  close() { this.sock.close(); }
}

const cliBin = skydomeBin();
const dir = tempDir('profile-bracket');
execFileSync(cliBin, ['synth', '-o', dir, '--size', String(size), '--evs=-2,0,2', '--quiet']);
const frames = readdirSync(dir).filter((f) => /^frame_\d+\.jpg$/.test(f)).sort().map((f) => path.join(dir, f));

const debug = (...a) => { if (process.env.PROFILE_DEBUG) console.error('[profile]', ...a); };
const server = await serve();
const p = await phone(server.origin);
let cdp = null;
try {
  await p.page.addInitScript(() => {
    navigator.mediaDevices.getUserMedia = () => Promise.reject(new DOMException('profiling without a camera', 'NotAllowedError'));
  });
  let version = null;
  for (let k = 0; k < 50 && !version; k++) {
    try { version = await (await fetch(`http://127.0.0.1:${port}/json/version`)).json(); } catch { await new Promise((r) => setTimeout(r, 100)); }
  }
  if (!version) throw new Error('no DevTools port');
  debug('browser', version.webSocketDebuggerUrl);
  cdp = new Cdp(version.webSocketDebuggerUrl);
  await cdp.open;

  /** sessionId -> {kind, url}; kind: page | worker (the core's) | pool | decoder | other. */
  const sessions = new Map();
  let profiling = false;
  const kindOf = (info, parent) => {
    if (info.type === 'page') return 'page';
    if (/worker\.js/.test(info.url)) return 'worker';
    if (/decoder\.js/.test(info.url)) return 'decoder';
    if (parent && parent.kind === 'worker') return 'pool';
    return 'other';
  };
  const prepare = async (sessionId) => {
    await cdp.send('Profiler.enable', {}, sessionId);
    await cdp.send('Profiler.setSamplingInterval', { interval }, sessionId);
    if (profiling) await cdp.send('Profiler.start', {}, sessionId);
  };
  cdp.handlers.push((m) => {
    if (m.method === 'Target.attachedToTarget') {
      const { sessionId, targetInfo, waitingForDebugger } = m.params;
      const kind = kindOf(targetInfo, sessions.get(m.sessionId));
      debug('attached', kind, targetInfo.type, targetInfo.url, waitingForDebugger);
      sessions.set(sessionId, { kind, url: targetInfo.url, alive: true });
      if (kind === 'other') { // the service worker: not part of a merge
        cdp.send('Runtime.runIfWaitingForDebugger', {}, sessionId).catch(() => {});
        cdp.send('Target.detachFromTarget', { sessionId }).catch(() => {});
        sessions.get(sessionId).alive = false;
        return;
      }
      (async () => {
        // Nested workers (the pool's) attach through their parent's session.
        await cdp.send('Target.setAutoAttach', { autoAttach: true, waitForDebuggerOnStart: true, flatten: true }, sessionId).catch(() => {});
        await prepare(sessionId).catch(() => {});
        if (waitingForDebugger) await cdp.send('Runtime.runIfWaitingForDebugger', {}, sessionId).catch(() => {});
      })();
    } else if (m.method === 'Target.detachedFromTarget') {
      const s = sessions.get(m.params.sessionId);
      if (s) s.alive = false;
    }
  });
  const { targetInfos } = await cdp.send('Target.getTargets');
  const pageTarget = targetInfos.find((t) => t.type === 'page');
  const { sessionId: pageSession } = await cdp.send('Target.attachToTarget', { targetId: pageTarget.targetId, flatten: true });
  sessions.set(pageSession, { kind: 'page', url: pageTarget.url, alive: true });
  await cdp.send('Target.setAutoAttach', { autoAttach: true, waitForDebuggerOnStart: true, flatten: true }, pageSession);
  await prepare(pageSession);

  // --trace CATS: Chromium's trace of the categories CATS (comma-separated; default V8's wasm
  // compilation) over both merges, summed per event name and thread, merge by merge.
  const traceCats = process.argv.includes('--trace')
    ? (arg('--trace', '') && !arg('--trace', '').startsWith('--') ? arg('--trace', '') : 'v8.wasm,disabled-by-default-v8.wasm.detailed,disabled-by-default-v8.wasm.turbofan,disabled-by-default-v8.compile').split(',')
    : null;
  const traceEvents = [];
  let traced = null;
  if (traceCats) {
    cdp.handlers.push((m) => {
      if (m.method === 'Tracing.dataCollected' && !m.sessionId) traceEvents.push(...m.params.value);
      if (m.method === 'Tracing.tracingComplete' && !m.sessionId && traced) traced();
    });
    await cdp.send('Tracing.start', {
      traceConfig: { includedCategories: [...traceCats, 'devtools.timeline', '__metadata'], recordMode: 'recordAsMuchAsPossible' },
      transferMode: 'ReportEvents',
    });
  }
  const query = new URLSearchParams();
  if (threads != null) query.set('threads', threads);
  if (reserve != null) query.set('reserve', reserve);
  if (warmup != null) query.set('warmup', warmup);
  await p.page.goto(`${server.origin}/${query.size ? `?${query}` : ''}`);
  debug('loaded');
  await onScreen(p.page, 'camera');
  debug('camera screen');
  await p.page.waitForFunction(() => document.body.dataset.core);
  await setSettings(p.page, { fisheye: true, sun: 'auto', north: '0', equirect: false });
  await p.page.waitForTimeout(idleMs);

  /** One merge of the bracket under the profiler: {coreMs, stages, profiles: [{kind, url, profile}]}. */
  const merge = async () => {
    profiling = !noCpu;
    const live = [...sessions].filter(([, s]) => s.alive);
    if (!noCpu) await Promise.all(live.map(([id]) => cdp.send('Profiler.start', {}, id, 5000).catch(() => {})));
    debug('profiling', live.map(([, s]) => s.kind));
    const since = await p.page.evaluate(() => Date.now());
    await p.page.setInputFiles('#gallery', [...frames, path.join(dir, 'times.txt')]);
    const msg = await resultOrError(p.page, since);
    debug('merge done', msg);
    if (msg) throw new Error(msg);
    profiling = false;
    const profiles = [];
    for (const [id, s] of sessions) {
      if (!s.alive || noCpu) continue;
      try {
        const { profile } = await cdp.send('Profiler.stop', {}, id);
        profiles.push({ kind: s.kind, url: s.url, profile });
      } catch { /* a worker that ended during the merge: its samples are lost */ }
    }
    return {
      coreMs: await p.page.evaluate(() => window.__skydomeCoreMs),
      stages: await p.page.evaluate(() => window.__skydomeStageMs),
      core: await p.page.evaluate(() => window.__skydomeCore),
      profiles,
    };
  };
  const mark = (label) => p.page.evaluate((l) => console.timeStamp(l), label);
  debug('merging');
  await mark('skydome-first-start');
  const first = await merge();
  await mark('skydome-first-end');
  debug('first merged');
  await p.page.waitForTimeout(1000);
  await mark('skydome-second-start');
  const second = await merge();
  await mark('skydome-second-end');
  if (traceCats) {
    const done = new Promise((resolve) => { traced = resolve; });
    await cdp.send('Tracing.end');
    await done;
    const at = (label) => {
      const e = traceEvents.find((x) => x.name === 'TimeStamp' && x.args && x.args.data && x.args.data.message === label);
      return e ? e.ts : NaN;
    };
    const windows = { first: [at('skydome-first-start'), at('skydome-first-end')], second: [at('skydome-second-start'), at('skydome-second-end')] };
    const threadName = new Map();
    for (const e of traceEvents) if (e.ph === 'M' && e.name === 'thread_name') threadName.set(`${e.pid}:${e.tid}`, e.args.name);
    // Complete events ('X') and begin/end pairs ('B'/'E') of the traced categories.
    const spans = [];
    const open = new Map();
    for (const e of traceEvents) {
      if (!traceCats.some((c) => e.cat && e.cat.split(',').includes(c))) continue;
      const key = `${e.pid}:${e.tid}`;
      if (e.ph === 'X') spans.push({ name: e.name, key, ts: e.ts, dur: e.dur || 0 });
      else if (e.ph === 'B') open.set(`${key}:${e.name}`, e);
      else if (e.ph === 'E') {
        const b = open.get(`${key}:${e.name}`);
        if (b) spans.push({ name: e.name, key, ts: b.ts, dur: e.ts - b.ts });
      }
    }
    for (const [label, [t0, t1]] of Object.entries(windows)) {
      const sums = new Map();
      for (const sp of spans) {
        if (!(sp.ts >= t0 && sp.ts <= t1)) continue;
        const k = `${(threadName.get(sp.key) || sp.key).replace(/\d+$/, '#')}\t${sp.name}`;
        const v = sums.get(k) || { ms: 0, n: 0 };
        sums.set(k, { ms: v.ms + sp.dur / 1000, n: v.n + 1 });
      }
      console.log(`\ntrace, ${label} merge (${((t1 - t0) / 1e6).toFixed(3)} s between the marks): ms, count, thread, event`);
      for (const [k, v] of [...sums].sort((a, b) => b[1].ms - a[1].ms).slice(0, top)) console.log(`${v.ms.toFixed(1).padStart(8)} ${String(v.n).padStart(6)}  ${k}`);
    }
    if (outPrefix) writeFileSync(`${outPrefix}.trace.json`, JSON.stringify(traceEvents));
  }

  /** Self time (ms) per "kind function" and per function, from samples and their time deltas. */
  const selfTimes = (run) => {
    const perKind = new Map();
    const total = new Map();
    for (const { kind, profile } of run.profiles) {
      const name = new Map(profile.nodes.map((n) => [n.id, n.callFrame.functionName || `(anonymous ${n.callFrame.url.split('/').pop()}:${n.callFrame.lineNumber})`]));
      profile.samples.forEach((id, i) => {
        const ms = (profile.timeDeltas[i + 1] ?? interval) / 1000;
        const f = name.get(id);
        perKind.set(`${kind}\t${f}`, (perKind.get(`${kind}\t${f}`) || 0) + ms);
        total.set(f, (total.get(f) || 0) + ms);
      });
    }
    return { perKind, total };
  };
  const a = selfTimes(first);
  const b = selfTimes(second);
  const fmt = (x) => x.toFixed(1).padStart(8);
  const table = (title, ma, mb) => {
    const keys = new Set([...ma.keys(), ...mb.keys()]);
    const rows = [...keys].map((k) => [k, ma.get(k) || 0, mb.get(k) || 0]).sort((x, y) => Math.abs(y[1] - y[2]) - Math.abs(x[1] - x[2]));
    console.log(`\n${title}: self ms, first / second / difference (largest differences first)`);
    for (const [k, x, y] of rows.slice(0, top)) console.log(`${fmt(x)} ${fmt(y)} ${fmt(x - y)}  ${k.slice(0, 140)}`);
    const sx = [...ma.values()].reduce((s, v) => s + v, 0);
    const sy = [...mb.values()].reduce((s, v) => s + v, 0);
    console.log(`${fmt(sx)} ${fmt(sy)} ${fmt(sx - sy)}  (all samples)`);
  };
  console.log(`core ${first.core && first.core.build} ${first.core && first.core.threads} threads`);
  console.log(`first merge: core ${(first.coreMs / 1000).toFixed(3)} s, stages ${JSON.stringify(Object.fromEntries(Object.entries(first.stages).map(([k, v]) => [k, Math.round(v)])))}`);
  console.log(`second merge: core ${(second.coreMs / 1000).toFixed(3)} s, stages ${JSON.stringify(Object.fromEntries(Object.entries(second.stages).map(([k, v]) => [k, Math.round(v)])))}`);
  console.log(`threads profiled: first ${first.profiles.map((x) => x.kind).join(', ')}; second ${second.profiles.map((x) => x.kind).join(', ')}`);
  table('all threads', a.total, b.total);
  table('per thread kind', a.perKind, b.perKind);
  if (outPrefix) {
    for (const [label, run] of [['first', first], ['second', second]]) {
      run.profiles.forEach(({ kind, profile }, i) => writeFileSync(`${outPrefix}.${label}.${kind}${i}.cpuprofile`, JSON.stringify(profile)));
    }
  }
} finally {
  if (cdp) cdp.close();
  await p.close();
  server.stop();
}
