// What a first-time user met (issue 24's defect list), each at a phone's size in portrait
// (390 × 844) and in landscape (844 × 390): the tests that would have caught them.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { existsSync, readFileSync, readdirSync } from 'node:fs';
import path from 'node:path';
import {
  cli, download, headerLines, onScreen, phone, resultOrError, screenshot, serve, setSettings, sharedData, tempDir,
} from './support.mjs';

const PORTRAIT = { width: 390, height: 844 };
const LANDSCAPE = { width: 844, height: 390 };
const VIEWPORTS = [['portrait', PORTRAIT], ['landscape', LANDSCAPE]];
const frobisher = path.join(sharedData, 'frobisher_001');
const noFrobisher = !existsSync(frobisher) && 'skipped: ../shared/data/frobisher_001 is absent';

let server;
before(async () => { server = await serve(); });
after(() => server && server.stop());

async function openApp(p, query = '') {
  await p.page.goto(`${server.origin}/${query}`, { waitUntil: 'domcontentloaded' });
  await onScreen(p.page, 'camera');
  await p.page.waitForFunction(() => document.body.dataset.core);
}

/** A synthetic fish-eye bracket: {frames, times (the times.txt path), dir}. */
function synth(size = 512, seed = 5) {
  const dir = tempDir('newuser');
  cli(['synth', '-o', dir, '--size', String(size), '--seed', String(seed), '--quiet']);
  const frames = readdirSync(dir).filter((f) => /^frame_\d+\.jpg$/.test(f)).sort().map((f) => path.join(dir, f));
  return { dir, frames, times: path.join(dir, 'times.txt') };
}

const FISHEYE = { fisheye: true, model: 'stereographic', fov: 235, sun: 'auto', north: '0' };
const cliFisheye = ['--fisheye', '--lens-model', 'stereographic', '--fov', '235', '--crop', '--north', '0', '--sun', 'auto'];

/** The app's .hdr equals the CLI's: the pixels byte for byte, every header line but two that
 *  print a full-precision float from trigonometry (wasm's and glibc's may differ in the last
 *  bit): the sun direction (to 1e-9°) and the absolute scale (to 1e-12 relative). */
function assertSameHdr(ours, theirs) {
  const [a, b] = [headerLines(ours), headerLines(theirs)];
  const loose = /^(#SUN_DIRECTION=|#UNITS=)/;
  const rest = (l) => l.filter((x) => !loose.test(x));
  const nums = (l) => l.filter((x) => loose.test(x)).join(' ').match(/-?\d+\.?\d*(e-?\d+)?/g) || [];
  const [na, nb] = [nums(a).map(Number), nums(b).map(Number)];
  assert.equal(na.length, nb.length);
  na.forEach((v, i) => assert.ok(Math.abs(v - nb[i]) <= 1e-12 * Math.max(1, Math.abs(nb[i])) + 1e-9, `${v} vs ${nb[i]}`));
  const words = (l) => l.filter((x) => loose.test(x)).map((x) => x.replace(/-?\d+\.?\d*(e-?\d+)?/g, '#'));
  assert.deepEqual(words(a), words(b));
  assert.deepEqual(rest(a), rest(b));
  const body = (bytes) => bytes.subarray(bytes.indexOf('\n\n') + 2);
  assert.ok(body(ours).equals(body(theirs)), 'pixel data byte-identical to the CLI\'s');
}

/** The element's box lies inside the viewport (nothing to scroll to reach it). */
async function inView(page, selector) {
  const box = await page.locator(selector).boundingBox();
  const vp = page.viewportSize();
  assert.ok(box, `${selector} is shown`);
  return box.y >= 0 && box.y + box.height <= vp.height && box.x >= 0 && box.x + box.width <= vp.width;
}

for (const [name, viewport] of VIEWPORTS) {
  test(`result (${name}): Save .hdr is above the fold, and saving confirms what was saved`, async () => {
    const s = synth();
    const p = await phone(server.origin, { viewport });
    try {
      await openApp(p);
      await setSettings(p.page, FISHEYE);
      const since = await p.page.evaluate(() => Date.now());
      await p.page.setInputFiles('#gallery', [...s.frames, s.times]);
      assert.equal(await resultOrError(p.page, since), null);
      await p.page.evaluate(() => window.scrollTo(0, 0));
      await screenshot(p.page, `newuser-result-${name}`);
      assert.ok(await inView(p.page, '#save-hdr'), 'Save .hdr is on the first screen');
      assert.ok(await inView(p.page, '#preview'), 'the whole preview is on the first screen');
      const hdr = await download(p.page, '#save-hdr');
      await p.page.waitForFunction(() => document.getElementById('message').className === 'info');
      const msg = await p.page.textContent('#message');
      assert.match(msg, new RegExp(`^Saved ${hdr.name.replace('.', '\\.')} \\(\\d`), msg);
      // The facts say what the numbers mean, with units.
      const facts = await p.page.textContent('#facts');
      assert.match(facts, /from north towards east/);
      assert.match(facts, /above the horizon/);
      assert.match(facts, /Sky luminance.*relative units/);
    } finally { await p.close(); }
  });

  test(`camera (${name}): the viewfinder and its circle fit the screen, the status line is on it, no formula jargon`, async () => {
    const p = await phone(server.origin, { viewport });
    try {
      await openApp(p);
      await p.page.waitForFunction(() => !document.getElementById('capture').disabled);
      await screenshot(p.page, `newuser-camera-${name}`);
      assert.ok(await inView(p.page, '.viewfinder'), 'the viewfinder fits the screen');
      assert.ok(await inView(p.page, '#camera-status'), 'the status line is on the first screen');
      assert.ok(await inView(p.page, '#capture'), 'Capture is on the first screen');
      const visible = await p.page.evaluate(() => document.getElementById('screen-camera').innerText);
      assert.ok(!/R·\(sin h/.test(visible), 'no formula on the camera screen');
    } finally { await p.close(); }
  });
}

test('camera: the fake camera\'s test pattern (a bright pie slice on green) is not taken for the lens circle', async () => {
  const p = await phone(server.origin, { viewport: PORTRAIT });
  try {
    await openApp(p);
    await setSettings(p.page, { fisheye: true });
    await p.page.waitForFunction(() => document.getElementById('lens-status').textContent.length > 0, null, { timeout: 60000 });
    const status = await p.page.textContent('#lens-status');
    // Found as "Lens circle r 240 px" before the finder asked for a dark housing around it.
    assert.match(status, /^No fish-eye circle in the camera picture yet/, status);
  } finally { await p.close(); }
});

/** Replaces the fake camera's takePhoto() (the same flat green picture whatever the exposure)
 *  by an ordinary scene without a fish-eye circle, exposed for the track's exposure time: a
 *  radiance ramp over 8 stops, left to right, through a 1/2.2 gamma, as PNG. */
function exposedOrdinaryScene() {
  let first = null;
  ImageCapture.prototype.takePhoto = async function takePhoto() {
    const t = this.track.getSettings().exposureTime;
    first = first || t;
    const [w, h] = [640, 480];
    const canvas = new OffscreenCanvas(w, h);
    const g = canvas.getContext('2d');
    const img = g.createImageData(w, h);
    for (let y = 0; y < h; y++) {
      for (let x = 0; x < w; x++) {
        const radiance = 2 ** (-6 + (8 * x) / w) * (1 + 0.3 * Math.sin(y / 17));
        const v = Math.min(1, 0.25 * radiance * (t / first));
        const i = 4 * (y * w + x);
        const z = 255 * v ** (1 / 2.2);
        img.data[i] = Math.round(z);
        img.data[i + 1] = Math.round(0.9 * z);
        img.data[i + 2] = Math.round(0.8 * z);
        img.data[i + 3] = 255;
      }
    }
    g.putImageData(img, 0, 0);
    return canvas.convertToBlob({ type: 'image/png' });
  };
}

test('capture path: a bracket without a fish-eye circle offers "Merge as ordinary photos", which merges it', async () => {
  const p = await phone(server.origin, { viewport: PORTRAIT });
  try {
    await p.page.addInitScript(exposedOrdinaryScene);
    await openApp(p);
    await setSettings(p.page, { fisheye: true });
    await p.page.waitForFunction(() => !document.getElementById('capture').disabled);
    let since = await p.page.evaluate(() => Date.now());
    await p.page.click('#capture');
    await p.page.waitForSelector('#squeezed:not([hidden])'); // the fake camera's 1–10 ms
    await p.page.click('#squeezed-merge');
    const msg = await resultOrError(p.page, since);
    assert.ok(msg, 'refused');
    assert.match(msg, /no fish-eye picture circle/, msg);
    await p.page.waitForSelector('#no-circle:not([hidden])');
    await screenshot(p.page, 'newuser-capture-no-circle');
    assert.ok(await inView(p.page, '#no-circle-plain'), 'the way out is on the screen');
    assert.equal(await p.page.isVisible('#no-circle-drag'), true, 'the circle can be given by hand');
    since = await p.page.evaluate(() => Date.now());
    await p.page.click('#no-circle-plain');
    assert.equal(await resultOrError(p.page, since), null);
    const report = await p.page.evaluate(() => document.body.dataset.screen);
    assert.equal(report, 'result');
  } finally { await p.close(); }
});

test('drag the circle: dragged and sized on the photo, the merge uses it and writes the CLI\'s bytes for that circle', { skip: noFrobisher }, async () => {
  const files = readdirSync(frobisher).filter((f) => /^IMG_.*\.jpg$/i.test(f)).sort().map((f) => path.join(frobisher, f));
  const p = await phone(server.origin, { viewport: PORTRAIT });
  try {
    await openApp(p);
    await setSettings(p.page, FISHEYE);
    let since = await p.page.evaluate(() => Date.now());
    await p.page.setInputFiles('#gallery', files);
    assert.ok(await resultOrError(p.page, since), 'no circle in an ordinary bracket');
    await p.page.waitForSelector('#no-circle-drag:not([hidden])');
    await p.page.click('#no-circle-drag');
    await p.page.waitForSelector('#circle-editor:not([hidden])');
    await p.page.waitForFunction(() => document.body.dataset.circle);
    const start = await p.page.evaluate(() => document.body.dataset.circle);
    // Drag the centre from the middle of the picture to 40 % across, 45 % down, by touch-like
    // pointer events, then size it with the slider.
    const box = await p.page.locator('#circle-svg').boundingBox();
    await p.page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
    await p.page.mouse.down();
    await p.page.mouse.move(box.x + 0.45 * box.width, box.y + 0.47 * box.height, { steps: 5 });
    await p.page.mouse.move(box.x + 0.4 * box.width, box.y + 0.45 * box.height, { steps: 5 });
    await p.page.mouse.up();
    const [w, h] = await p.page.evaluate(() => [document.getElementById('circle-photo').naturalWidth, document.getElementById('circle-photo').naturalHeight]);
    const radius = Math.round(0.3 * Math.max(w, h));
    await p.page.locator('#circle-r').fill(String(radius));
    const moved = await p.page.evaluate(() => document.body.dataset.circle);
    assert.notEqual(moved, start, 'the circle moved');
    const [cx, cy, r] = moved.split(',').map(Number);
    assert.ok(Math.abs(cx - 0.4 * w) <= 0.01 * w && Math.abs(cy - 0.45 * h) <= 0.01 * h, `centre ${cx},${cy} where it was dropped (${0.4 * w},${0.45 * h})`);
    assert.equal(r, radius);
    since = await p.page.evaluate(() => Date.now());
    await p.page.click('#circle-use');
    assert.equal(await resultOrError(p.page, since), null);
    const out = tempDir('drag');
    cli(['merge', ...files, '--fisheye', '--circle', moved, '--lens-model', 'stereographic', '--fov', '235', '--crop', '--north', '0', '--sun', 'auto', '-o', path.join(out, 'cli.hdr'), '--quiet']);
    const hdr = await download(p.page, '#save-hdr');
    assertSameHdr(hdr.bytes, readFileSync(path.join(out, 'cli.hdr')));
  } finally { await p.close(); }
});

/** Mean luminance (0–255) and the fraction of pixels at 250 or more of a JPEG, as the page
 *  decodes it, and the mean absolute difference from a second JPEG of the same size. */
async function pictureStats(page, jpeg, other) {
  return page.evaluate(async ([a, b]) => {
    const pixels = async (b64) => {
      const img = new Image();
      img.src = `data:image/jpeg;base64,${b64}`;
      await img.decode();
      const c = document.createElement('canvas');
      c.width = img.naturalWidth;
      c.height = img.naturalHeight;
      const g = c.getContext('2d');
      g.drawImage(img, 0, 0);
      return g.getImageData(0, 0, c.width, c.height).data;
    };
    const [p, q] = [await pixels(a), await pixels(b)];
    let [sum, sat, diff] = [0, 0, 0];
    for (let i = 0; i < p.length; i += 4) {
      const l = (p[i] + p[i + 1] + p[i + 2]) / 3;
      sum += l;
      if (l >= 250) sat++;
      diff += Math.abs(l - (q[i] + q[i + 1] + q[i + 2]) / 3);
    }
    const n = p.length / 4;
    return { mean: sum / n, saturated: sat / n, meanDiff: diff / n, same: p.length === q.length };
  }, [jpeg.toString('base64'), other.toString('base64')]);
}

test('a 9-frame bracket (±4 EV): the preview is the CLI\'s, not blown out', async () => {
  const dir = tempDir('nine');
  cli(['synth', '-o', dir, '--size', '1200', '--seed', '9', '--evs=-4,-3,-2,-1,0,1,2,3,4', '--quiet']);
  const frames = readdirSync(dir).filter((f) => /^frame_\d+\.jpg$/.test(f)).sort().map((f) => path.join(dir, f));
  assert.equal(frames.length, 9);
  const cliJpg = path.join(dir, 'cli.jpg');
  cli(['merge', ...frames, '--times-file', path.join(dir, 'times.txt'), ...cliFisheye, '--preview', cliJpg, '-o', path.join(dir, 'cli.hdr'), '--quiet']);
  const p = await phone(server.origin, { viewport: PORTRAIT });
  try {
    await openApp(p);
    await setSettings(p.page, FISHEYE);
    const since = await p.page.evaluate(() => Date.now());
    await p.page.setInputFiles('#gallery', [...frames, path.join(dir, 'times.txt')]);
    assert.equal(await resultOrError(p.page, since), null);
    const hdr = await download(p.page, '#save-hdr');
    assertSameHdr(hdr.bytes, readFileSync(path.join(dir, 'cli.hdr')));
    const jpg = await download(p.page, '#save-jpg');
    const ours = await pictureStats(p.page, jpg.bytes, readFileSync(cliJpg));
    const theirs = await pictureStats(p.page, readFileSync(cliJpg), jpg.bytes);
    assert.ok(ours.same, 'the same size as the CLI\'s preview');
    // The JPEG encoders of wasm and x86 round a few coefficients differently: within a level.
    assert.ok(ours.meanDiff < 1, `mean difference ${ours.meanDiff} levels from the CLI's preview`);
    assert.ok(Math.abs(ours.mean - theirs.mean) < 0.5, `mean ${ours.mean} vs the CLI's ${theirs.mean}`);
    assert.ok(ours.saturated < 0.01, `${(100 * ours.saturated).toFixed(2)} % of the preview is blown out`);
  } finally { await p.close(); }
});

test('pick photos without exposure times: a field per photo, the picker takes times.txt, the CLI\'s bytes', async () => {
  const s = synth(384, 8);
  const out = path.join(s.dir, 'cli.hdr');
  cli(['merge', ...s.frames, '--times-file', s.times, ...cliFisheye, '-o', out, '--quiet']);
  const expected = readFileSync(out);
  const times = Object.fromEntries(readFileSync(s.times, 'utf8').split('\n').filter((l) => l.trim() && !l.startsWith('#'))
    .map((l) => l.trim().split(/\s+/)).map(([f, t]) => [path.basename(f), t]));
  const p = await phone(server.origin, { viewport: PORTRAIT });
  try {
    await openApp(p);
    const accept = await p.page.getAttribute('#gallery', 'accept');
    assert.match(accept, /\.txt/, `the picker lets Android pick times.txt: ${accept}`);
    await setSettings(p.page, FISHEYE);
    await p.page.setInputFiles('#gallery', s.frames);
    await p.page.waitForSelector('#times-form:not([hidden])');
    const fields = await p.page.$$('#times-list input');
    assert.equal(fields.length, 3);
    assert.ok(await inView(p.page, '#times-list li:first-child input'), 'the first field is on the screen');
    assert.equal(await p.page.evaluate(() => document.getElementById('message').hidden), true, 'no error, a question');
    await screenshot(p.page, 'newuser-times-form');
    for (const [i, f] of s.frames.entries()) await fields[i].fill(times[path.basename(f)]);
    const since = await p.page.evaluate(() => Date.now());
    await p.page.click('#times-merge');
    assert.equal(await resultOrError(p.page, since), null);
    const hdr = await download(p.page, '#save-hdr');
    assertSameHdr(hdr.bytes, expected);
  } finally { await p.close(); }
});

test('an ordinary bracket with the fish-eye setting on: one plain sentence, then "Merge as ordinary photos" gives the CLI\'s bytes', { skip: noFrobisher }, async () => {
  const files = readdirSync(frobisher).filter((f) => /^IMG_.*\.jpg$/i.test(f)).sort().map((f) => path.join(frobisher, f));
  const out = tempDir('plain');
  cli(['merge', ...files, '-o', path.join(out, 'cli.hdr'), '--quiet']);
  const expected = readFileSync(path.join(out, 'cli.hdr'));
  const p = await phone(server.origin, { viewport: LANDSCAPE });
  try {
    await openApp(p);
    await setSettings(p.page, { fisheye: true });
    let since = await p.page.evaluate(() => Date.now());
    await p.page.setInputFiles('#gallery', files);
    const msg = await resultOrError(p.page, since);
    assert.ok(msg, 'refused');
    assert.ok(!/\(.*\(/.test(msg), `no nested parentheses: ${msg}`);
    assert.match(msg, /no fish-eye picture circle/);
    await p.page.waitForSelector('#no-circle:not([hidden])');
    await screenshot(p.page, 'newuser-no-circle');
    assert.ok(await inView(p.page, '#no-circle-plain'), 'the way out is on the screen');
    assert.equal(await p.page.isVisible('#no-circle-drag'), true, 'the circle can be given by hand');
    since = await p.page.evaluate(() => Date.now());
    await p.page.click('#no-circle-plain');
    assert.equal(await resultOrError(p.page, since), null);
    const hdr = await download(p.page, '#save-hdr');
    assert.ok(hdr.bytes.equals(expected), 'byte-identical to skydome merge without --fisheye');
  } finally { await p.close(); }
});

test('progress in words, a fresh bar, Settings locked while merging, Cancel leaves only its own notice', async () => {
  const s = synth(3000, 3);
  const p = await phone(server.origin, { viewport: PORTRAIT });
  try {
    await openApp(p);
    await setSettings(p.page, FISHEYE);
    // Every text the stage line and bar show, from the moment the work screen appears.
    await p.page.evaluate(() => {
      window.__seen = [];
      const note = () => window.__seen.push({ text: document.getElementById('stage').textContent, value: document.getElementById('progress').value, screen: document.body.dataset.screen });
      new MutationObserver(note).observe(document.getElementById('stage'), { childList: true, characterData: true, subtree: true });
      new MutationObserver(note).observe(document.body, { attributes: true, attributeFilter: ['data-screen'] });
    });
    let since = await p.page.evaluate(() => Date.now());
    await p.page.setInputFiles('#gallery', [...s.frames, s.times]);
    assert.equal(await resultOrError(p.page, since), null);
    let seen = await p.page.evaluate(() => window.__seen);
    const texts = seen.filter((x) => x.screen === 'work').map((x) => x.text);
    assert.ok(texts.some((t) => /^Merging the exposures… \d+ %$/.test(t)), texts.join(' | '));
    assert.ok(!texts.some((t) => /^(decoding|lens|calibrating|merging|sky|pictures)\b/.test(t)), `no raw stage names: ${texts.join(' | ')}`);
    // A second job starts with an empty bar.
    await p.page.evaluate(() => { window.__seen = []; });
    await p.page.click('#back');
    since = await p.page.evaluate(() => Date.now());
    await p.page.setInputFiles('#gallery', [...s.frames, s.times]);
    await onScreen(p.page, 'work');
    seen = await p.page.evaluate(() => window.__seen);
    const first = seen.find((x) => x.screen === 'work');
    assert.ok(first && first.value === 0, `the bar starts empty: ${JSON.stringify(first)}`);
    assert.equal(await p.page.isDisabled('#to-settings'), true, 'Settings cannot be opened during a merge');
    await p.page.click('#cancel');
    await onScreen(p.page, 'camera');
    await p.page.waitForTimeout(1500);
    const m = await p.page.evaluate(() => ({ cls: document.getElementById('message').className, text: document.getElementById('message').textContent }));
    assert.deepEqual(m, { cls: 'info', text: 'Cancelled: nothing was saved.' });
    assert.equal(await p.page.isDisabled('#to-settings'), false);
    assert.deepEqual(p.errors, []);
  } finally { await p.close(); }
});

test('meter readings: a lux reading makes the dome absolute, as skydome merge --illuminance; false colour in cd/m²', async () => {
  const s = synth(512, 9);
  const lux = 20000;
  const out = path.join(s.dir, 'cli.hdr');
  cli(['merge', ...s.frames, '--times-file', s.times, ...cliFisheye, '--illuminance', String(lux), '-o', out, '--quiet']);
  const expected = readFileSync(out);
  const p = await phone(server.origin, { viewport: PORTRAIT });
  try {
    await openApp(p);
    await setSettings(p.page, FISHEYE);
    let since = await p.page.evaluate(() => Date.now());
    await p.page.setInputFiles('#gallery', [...s.frames, s.times]);
    assert.equal(await resultOrError(p.page, since), null);
    assert.match(await p.page.textContent('#facts'), /needs a meter reading/);
    await p.page.click('#meter summary');
    await p.page.fill('#meter-lux', String(lux));
    since = await p.page.evaluate(() => Date.now());
    await p.page.click('#meter-apply');
    assert.equal(await resultOrError(p.page, since), null);
    const facts = await p.page.textContent('#facts');
    assert.match(facts, /Horizontal illuminance20 000 lux/, facts);
    assert.match(facts, /Sky luminance[\d. ]+ to [\d. ]+ cd\/m²/, facts);
    const hdr = await download(p.page, '#save-hdr');
    assertSameHdr(hdr.bytes, expected);
    await p.page.click('#view-toggle');
    await p.page.waitForFunction(() => document.body.dataset.view === 'false-colour' && document.getElementById('false-colour').naturalWidth > 0);
    assert.match(await p.page.textContent('#view-toggle'), /cd\/m²/);
    await screenshot(p.page, 'newuser-false-colour');
    assert.deepEqual(p.errors, []);
  } finally { await p.close(); }
});
