// The app's wasm decodes JPEGs exactly as the command line does. Its JPEG decoder runs
// WebAssembly SIMD code where the native build runs AVX2, NEON or scalar code
// (vendor/zune-jpeg/PATCHED.md); the fixtures in web-tests/fixtures/jpeg/ cover the decoder's
// paths (4:4:4, 4:2:2, 4:2:0, 4:4:0, greyscale, progressive, restart intervals, odd sizes, a
// width below 16, quality 25 and 100, clamping colours) and native.json holds the digests of
// their native decodes, which crates/skydome-web/tests/jpeg_fixtures.rs checks natively. Here
// the built app's two cores (pkg and pkg-mt, loaded in Node) decode the same files through the
// app's own decoding entry point (`decode_photo`, what its decoding workers call); one code in
// one pixel different fails the test.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { existsSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { pathToFileURL } from 'node:url';
import { appDir, root } from './support.mjs';

const fixtures = path.join(root, 'web-tests/fixtures/jpeg');
const native = JSON.parse(readFileSync(path.join(fixtures, 'native.json'), 'utf8'));

/** 64-bit FNV-1a as 16 hex digits (as jpeg_fixtures.rs). */
function fnv1a64(bytes) {
  let h = 0xcbf29ce484222325n;
  const prime = 0x100000001b3n;
  const mask = 0xffffffffffffffffn;
  for (const b of bytes) h = ((h ^ BigInt(b)) * prime) & mask;
  return h.toString(16).padStart(16, '0');
}

/** Loads the core in `pkg` of the built app; returns its module (initialised). */
async function core(pkg) {
  const dir = path.join(appDir, pkg);
  if (!existsSync(path.join(dir, 'skydome_web_bg.wasm'))) {
    throw new Error(`${dir}: the app is not built; run crates/skydome-web/build.sh`);
  }
  // The threaded core's worker helper (wasm-bindgen-rayon) listens on `self` when loaded; Node
  // has no `self`. No pool is started here: `decode_photo` runs on this thread, which is all a
  // decoding worker of the app does.
  globalThis.self ??= new EventTarget();
  const m = await import(pathToFileURL(path.join(dir, 'skydome_web.js')).href);
  m.initSync({ module: readFileSync(path.join(dir, 'skydome_web_bg.wasm')) });
  return m;
}

/** Decodes every fixture with `m`; returns the names whose pixels differ from the native decode. */
function mismatches(m) {
  const bad = [];
  for (const [file, want] of Object.entries(native)) {
    const photo = m.decode_photo(file, readFileSync(path.join(fixtures, file)));
    const meta = JSON.parse(photo.meta_json());
    const pixels = photo.take_pixels();
    photo.free();
    assert.equal(meta.width, want.width, file);
    assert.equal(meta.height, want.height, file);
    assert.equal(pixels.length, 3 * want.width * want.height, file);
    const got = fnv1a64(pixels);
    if (got !== want.fnv1a64) bad.push(`${file} (${got}, native ${want.fnv1a64})`);
  }
  return bad;
}

test('the fixtures cover the decoder paths named in native.json', () => {
  const names = Object.keys(native);
  assert.ok(names.length >= 10, `${names.length} fixtures`);
  for (const kind of ['rgb444', 'rgb422', 'rgb420', 'rgb440', 'grey', 'progressive', 'restart', 'q100', 'q25', '13x9']) {
    assert.ok(names.some((n) => n.includes(kind)), `a fixture for ${kind}`);
  }
});

test('the single-threaded core decodes every fixture JPEG exactly as the native build', async () => {
  const bad = mismatches(await core('pkg'));
  assert.deepEqual(bad, [], `decoded pixels differ from the native decode: ${bad.join(', ')}`);
});

test('the threaded core decodes every fixture JPEG exactly as the native build', async (t) => {
  if (!existsSync(path.join(appDir, 'pkg-mt', 'skydome_web_bg.wasm'))) {
    // build.sh with SKYDOME_WEB_THREADS=0 builds no threaded core; the app then never loads one.
    t.skip('no threaded core in this build (SKYDOME_WEB_THREADS=0)');
    return;
  }
  const bad = mismatches(await core('pkg-mt'));
  assert.deepEqual(bad, [], `decoded pixels differ from the native decode: ${bad.join(', ')}`);
});
