// The two cores: the threaded one (pkg-mt, rayon on Web Workers) when the page is
// cross-origin isolated, the single-threaded one (pkg) when it is not; both write the command
// line's bytes. Also the service worker's isolation shim for hosts that cannot send headers.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { existsSync, readFileSync, readdirSync } from 'node:fs';
import path from 'node:path';
import {
  appDir, cli, download, headerLines, onScreen, phone, resultOrError, serve, setSettings, tempDir,
} from './support.mjs';

const threadedBuilt = existsSync(path.join(appDir, 'pkg-mt', 'skydome_web_bg.wasm'));

/** A small synthetic fish-eye bracket and the CLI's .hdr of it (sun detected, north 0). */
function bracket() {
  const dir = tempDir('threads');
  cli(['synth', '-o', dir, '--size', '512', '--seed', '11', '--quiet']);
  const frames = readdirSync(dir).filter((f) => /^frame_\d+\.jpg$/.test(f)).sort().map((f) => path.join(dir, f));
  const out = path.join(dir, 'cli.hdr');
  cli(['merge', ...frames, '--times-file', path.join(dir, 'times.txt'), '--fisheye', '--lens-model', 'stereographic',
    '--fov', '235', '--crop', '--north', '0', '--sun', 'auto', '-o', out, '--quiet']);
  return { files: [...frames, path.join(dir, 'times.txt')], expected: readFileSync(out) };
}

/** The app's .hdr equals the CLI's: every header line but the full-precision sun direction
 *  comment (wasm's and glibc's trigonometry may differ in its last bit; compared to 1e-9°),
 *  and the pixels byte for byte. */
function assertCliBytes(ours, theirs) {
  const [a, b] = [headerLines(ours), headerLines(theirs)];
  const dir = (l) => l.filter((x) => x.startsWith('#SUN_DIRECTION=')).join(' ').match(/-?\d+\.?\d*(e-?\d+)?/g) || [];
  const [da, db] = [dir(a).map(Number), dir(b).map(Number)];
  assert.equal(da.length, db.length);
  da.forEach((v, i) => assert.ok(Math.abs(v - db[i]) < 1e-9, `${v} vs ${db[i]}`));
  const rest = (l) => l.filter((x) => !x.startsWith('#SUN_DIRECTION='));
  assert.deepEqual(rest(a), rest(b));
  const body = (bytes) => bytes.subarray(bytes.indexOf('\n\n') + 2);
  assert.ok(body(ours).equals(body(theirs)), 'pixel data byte-identical to the CLI\'s');
}

/** Loads the app at `query`, waits for its core, merges `files`; returns {core, threads, hdr}. */
async function mergeIn(p, origin, files, query = '', { sw = true } = {}) {
  await p.page.goto(`${origin}/${query}`, { waitUntil: 'domcontentloaded' });
  await onScreen(p.page, 'camera');
  if (sw) await p.page.waitForFunction(() => navigator.serviceWorker && navigator.serviceWorker.controller);
  await p.page.waitForFunction(() => document.body.dataset.core);
  await setSettings(p.page, { fisheye: true, model: 'stereographic', fov: 235, sun: 'auto', north: '0' });
  const since = await p.page.evaluate(() => Date.now());
  await p.page.setInputFiles('#gallery', files);
  const msg = await resultOrError(p.page, since);
  assert.equal(msg, null, `no error: ${msg}`);
  const core = await p.page.evaluate(() => ({ ...window.__skydomeCore }));
  const facts = await p.page.textContent('#facts');
  const hdr = await download(p.page, '#save-hdr');
  return { ...core, facts, hdr: hdr.bytes };
}

test('isolated page: the threaded core runs on a pool and writes the CLI\'s bytes; ?threads=0 the single one, same bytes', { skip: !threadedBuilt && 'skipped: the threaded core was not built (SKYDOME_WEB_THREADS=0)' }, async () => {
  const { files, expected } = bracket();
  const server = await serve();
  const p = await phone(server.origin);
  try {
    const mt = await mergeIn(p, server.origin, files, '?threads=2');
    assert.equal(await p.page.evaluate(() => crossOriginIsolated), true);
    assert.equal(mt.build, 'threaded');
    assert.equal(mt.threads, 2);
    assert.match(mt.facts, /on 2 threads/);
    assertCliBytes(mt.hdr, expected);
    const st = await mergeIn(p, server.origin, files, '?threads=0');
    assert.equal(st.build, 'single');
    assert.match(st.facts, /on one thread/);
    assertCliBytes(st.hdr, expected);
    assert.deepEqual(p.errors, []);
  } finally { await p.close(); server.stop(); }
});

// The idle warm-up (worker.js): the decoding warm-up, the reservation, the 256² merge, then four
// rounds of skydome_web::warm_up_stages, which make V8 optimise what a 12 MP merge calls once
// per picture (lens circle, tone map and statistics, checks, noise fit, merge). Each round
// reports the stages that ran and gave what they should; if one stopped (or failed early),
// the first merge would again run it in baseline code, and this fails.
const WARM_UP_STAGES = ['lens circle', 'preview tone map', 'luminance statistics', 'bracket checks, noise fit and merge', 'the whole pipeline'];
test('the idle warm-up runs all its steps and every stage of its stages rounds, in both cores', async () => {
  const server = await serve();
  const p = await phone(server.origin);
  try {
    for (const query of threadedBuilt ? ['?threads=2', '?threads=0'] : ['?threads=0']) {
      await p.page.goto(`${server.origin}/${query}`);
      await onScreen(p.page, 'camera');
      await p.page.waitForFunction(() => document.body.dataset.core);
      const t0 = Date.now();
      let w = await p.page.evaluate(() => window.__skydomeAsk('warmUp'));
      while (w.stages.length < 4 && Date.now() - t0 < 60000) {
        await p.page.waitForTimeout(250);
        w = await p.page.evaluate(() => window.__skydomeAsk('warmUp'));
      }
      assert.equal(w.ms.length, 7, `${query}: decoding, reservation, 256² merge and four stages rounds (${w.ms})`);
      assert.equal(w.stages.length, 4, query);
      for (const ran of w.stages) assert.deepEqual(ran, WARM_UP_STAGES, query);
    }
    assert.deepEqual(p.errors, []);
  } finally { await p.close(); server.stop(); }
});

test('page not isolated (no headers, no service worker): the single-threaded core, the CLI\'s bytes', async () => {
  const { files, expected } = bracket();
  const server = await serve(appDir, { isolation: false });
  const p = await phone(server.origin, { serviceWorkers: 'block' });
  try {
    const r = await mergeIn(p, server.origin, files, '', { sw: false });
    assert.equal(await p.page.evaluate(() => crossOriginIsolated), false);
    assert.equal(r.build, 'single');
    assert.equal(r.threads, 1);
    assertCliBytes(r.hdr, expected);
    assert.deepEqual(p.errors, []);
  } finally { await p.close(); server.stop(); }
});

test('host without headers: the service worker isolates the page after one reload and the threaded core runs', { skip: !threadedBuilt && 'skipped: the threaded core was not built' }, async () => {
  const server = await serve(appDir, { isolation: false });
  const p = await phone(server.origin);
  try {
    await p.page.goto(`${server.origin}/?threads=2`, { waitUntil: 'domcontentloaded' });
    // The first load is not isolated; the page reloads itself once the service worker controls it.
    await p.page.waitForFunction(() => crossOriginIsolated && document.body.dataset.core === 'threaded', null, { timeout: 60000 });
    assert.equal(await p.page.evaluate(() => sessionStorage.getItem('skydome.isolationReload')), '1');
    assert.equal(await p.page.evaluate(() => document.body.dataset.threads), '2');
    assert.deepEqual(p.errors, []);
  } finally { await p.close(); server.stop(); }
});
