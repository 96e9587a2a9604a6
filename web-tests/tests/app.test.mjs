// The phone app in a real browser (headless Chromium, phone viewport, touch, fake camera).
// Each test checks that no request left the app's origin.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { cpSync, existsSync, readFileSync, readdirSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import {
  appDir, cli, cliError, download, headerLines, onScreen, phone, resultOrError, screenshot, serve, setSettings,
  sharedData, tempDir, root,
} from './support.mjs';

let server;
before(async () => { server = await serve(); });
after(() => server && server.stop());

async function openApp(p) {
  await p.page.goto(`${server.origin}/`, { waitUntil: 'domcontentloaded' });
  await onScreen(p.page, 'camera');
  // The service worker controls the page once it is installed and claimed.
  await p.page.waitForFunction(() => navigator.serviceWorker && navigator.serviceWorker.controller);
}

function assertStayedHome(p) {
  assert.deepEqual(p.foreign(), [], 'requests left the page\'s origin');
  assert.deepEqual(p.errors, [], 'uncaught errors in the page');
}

function oneSentence(msg) {
  assert.ok(msg, 'an error message is shown');
  assert.ok(!msg.includes('\n'), `one line: ${msg}`);
  assert.match(msg, /^\S.*[.!?]$/, `a sentence: ${msg}`);
  assert.ok(!/ at .*\.(js|rs):\d+/.test(msg), `no stack trace: ${msg}`);
  assert.equal(msg.split(/[.!?](\s|$)/).filter((s) => s && s.trim()).length, 1, `one sentence: ${msg}`);
}

async function pickFiles(page, files) {
  const since = await page.evaluate(() => Date.now());
  await page.setInputFiles('#gallery', files);
  return since;
}

test('capture path: three exposures requested and read back, the core refuses identical frames', async () => {
  const p = await phone(server.origin);
  try {
    await openApp(p);
    await p.page.waitForFunction(() => !document.getElementById('capture').disabled);
    await screenshot(p.page, '1-camera');
    const status = await p.page.textContent('#camera-status');
    assert.match(status, /Manual exposure/, status);
    // The fake camera offers 1–10 ms: three photos 2 EV apart (16×) do not fit, so the bracket
    // is squeezed. The app says what it took and asks; "Take again" merges nothing.
    await p.page.click('#capture');
    await p.page.waitForSelector('#squeezed:not([hidden])');
    const squeezed = await p.page.textContent('#squeezed-text');
    assert.match(squeezed, /could not hold 3 photos 2 EV apart: it took 1\/1000, 1\/\d+, 1\/100 s, \d\.\d and \d\.\d EV apart/, squeezed);
    assert.ok(await p.page.evaluate(() => document.getElementById('message').hidden), 'nothing merged yet');
    await p.page.click('#squeezed-retake');
    assert.match(await p.page.textContent('#camera-status'), /Not merged/);
    await p.page.waitForFunction(() => !document.getElementById('capture').disabled);
    const since = await p.page.evaluate(() => Date.now());
    await p.page.click('#capture');
    await p.page.waitForSelector('#squeezed:not([hidden])');
    await p.page.click('#squeezed-merge');
    const msg = await resultOrError(p.page, since);
    const cap = JSON.parse(await p.page.evaluate(() => document.body.dataset.capture || 'null'));
    assert.ok(cap, 'the bracket was taken');
    assert.equal(cap.requested.length, 3);
    assert.equal(new Set(cap.requested).size, 3, `three different times: ${cap.requested}`);
    assert.deepEqual(cap.readBack, cap.requested, 'getSettings() reports the requested times');
    assert.equal(cap.steps.length, 2, `the steps taken are reported: ${cap.steps}`);
    // The fake camera's photos are identical whatever the exposure: the core refuses them.
    oneSentence(msg);
    assert.match(msg, /identical/i, msg);
    // Named as the user knows them, the honoured times not blamed, the way out named.
    assert.match(msg, /^Photo \d of 3(, photo \d of 3)* and photo \d of 3 came out nearly identical although/, msg);
    assert.ok(!/shot_|auto-exposure|auto-ISO/.test(msg), msg);
    assert.match(msg, /Pick photos/, msg);
    assert.equal(await p.page.evaluate(() => document.body.dataset.screen), 'camera');
    await screenshot(p.page, '2-capture-refused');
    assertStayedHome(p);
  } finally { await p.close(); }
});

test('gallery path: a real bracket gives the same .hdr bytes as skydome merge', { skip: !existsSync(path.join(sharedData, 'frobisher_001')) && 'skipped: ../shared/data/frobisher_001 is absent' }, async () => {
  const dir = path.join(sharedData, 'frobisher_001');
  const files = readdirSync(dir).filter((f) => /^IMG_.*\.jpg$/i.test(f)).sort().map((f) => path.join(dir, f));
  assert.equal(files.length, 3);
  const out = tempDir('frobisher');
  cli(['merge', ...files, '-o', path.join(out, 'cli.hdr'), '--quiet']);
  const expected = readFileSync(path.join(out, 'cli.hdr'));

  const p = await phone(server.origin);
  try {
    await openApp(p);
    await setSettings(p.page, { fisheye: false });
    const since = await pickFiles(p.page, files);
    // The small bracket may be merged before the work screen is seen: only photograph it then.
    if (await p.page.evaluate(() => document.body.dataset.screen === 'work')) await screenshot(p.page, '3-merging');
    const msg = await resultOrError(p.page, since);
    assert.equal(msg, null, `no error: ${msg}`);
    await onScreen(p.page, 'result');
    await screenshot(p.page, '4-result-frobisher');
    const hdr = await download(p.page, '#save-hdr');
    assert.match(hdr.name, /\.hdr$/);
    assert.equal(hdr.bytes.length, expected.length, 'same size as the CLI\'s file');
    assert.ok(hdr.bytes.equals(expected), 'byte-identical to skydome merge');
    const jpg = await download(p.page, '#save-jpg');
    assert.deepEqual([...jpg.bytes.subarray(0, 3)], [0xff, 0xd8, 0xff], 'a JPEG preview');
    const exr = await download(p.page, '#save-exr');
    assert.deepEqual([...exr.bytes.subarray(0, 4)], [0x76, 0x2f, 0x31, 0x01], 'an OpenEXR file');
    // The calibration was stored as a profile, exportable as the CLI's camera.json.
    await p.page.click('#to-settings');
    await p.page.waitForSelector('#profiles li button');
    const exported = await download(p.page, '#profiles li button:nth-child(2)');
    const prof = JSON.parse(exported.bytes.toString('utf8'));
    assert.equal(prof.version, 1);
    assert.equal(prof.g.length, 3);
    assert.equal(prof.g[0].length, 256);
    await screenshot(p.page, '5-settings');
    assertStayedHome(p);
  } finally { await p.close(); }
});

/** Sets the compass through DevTools: the absolute-orientation virtual sensor, whose readings
 *  Chromium turns into `deviceorientationabsolute` events. A phone lying flat with its top edge
 *  at compass heading h is rotated by alpha = 360° − h about the vertical: quaternion
 *  (0, 0, sin(alpha/2), cos(alpha/2)). Set before the page loads, so the first event has it. */
async function setHeading(page, heading) {
  let cdp = page.__cdp;
  if (!cdp) {
    cdp = page.__cdp = await page.context().newCDPSession(page);
    // Once per page: Chromium refuses a second override of the same sensor.
    await cdp.send('Emulation.setSensorOverrideEnabled', { enabled: true, type: 'absolute-orientation', metadata: { available: true } });
  }
  const half = (((360 - heading) % 360) * Math.PI) / 360;
  await cdp.send('Emulation.setSensorOverrideReadings', {
    type: 'absolute-orientation',
    reading: { quaternion: { x: 0, y: 0, z: Math.sin(half), w: Math.cos(half) } },
  });
}

/** Sets the compass to `heading` and waits until the page shows it (the first reading may
 *  precede the page's listener, so it is sent again until it arrives). */
async function compassAt(page, heading) {
  await setHeading(page, heading);
  for (let i = 0; ; i++) {
    const shown = await page.waitForFunction((h) => document.getElementById('heading').textContent.startsWith(`${h.toFixed(1)}°`), heading, { timeout: 5000 }).then(() => true, () => false);
    if (shown) return;
    assert.ok(i < 6, 'the compass heading reaches the page');
    await setHeading(page, heading + 1e-9);
  }
}

test('fish-eye path: tapped sun and compass north give the CLI\'s #SUN and #NORTH lines', async () => {
  const synth = tempDir('synth');
  cli(['synth', '-o', synth, '--size', '512', '--seed', '7', '--quiet']);
  const frames = readdirSync(synth).filter((f) => /^frame_\d+\.jpg$/.test(f)).sort().map((f) => path.join(synth, f));
  assert.equal(frames.length, 3);
  const heading = 37;

  const p = await phone(server.origin);
  try {
    await p.page.goto('about:blank');
    await setHeading(p.page, heading);
    await openApp(p);
    await setSettings(p.page, { fisheye: true, model: 'stereographic', fov: 235, sun: 'auto', north: '' });
    await compassAt(p.page, heading);
    await screenshot(p.page, '6-camera-compass');
    let since = await pickFiles(p.page, [...frames, path.join(synth, 'times.txt')]);
    let msg = await resultOrError(p.page, since);
    assert.equal(msg, null, `no error: ${msg}`);
    // Double-tap the sun where the preview shows it, a little off the detected centre (a finger).
    const box = await p.page.locator('#preview').boundingBox();
    const sunText = await p.page.textContent('#facts');
    assert.match(sunText, /Sun/);
    const pos = await p.page.evaluate(() => {
      const m = document.getElementById('sun-mark');
      return m.hidden ? null : [parseFloat(m.style.left), parseFloat(m.style.top)];
    });
    assert.ok(pos, `the sun was detected: ${sunText}`);
    const tx = box.x + (box.width * pos[0]) / 100 + 3;
    const ty = box.y + (box.height * pos[1]) / 100 - 2;
    since = await p.page.evaluate(() => Date.now());
    await p.page.touchscreen.tap(tx, ty);
    await p.page.waitForTimeout(120);
    await p.page.touchscreen.tap(tx, ty);
    msg = await resultOrError(p.page, since);
    assert.equal(msg, null, `no error: ${msg}`);
    const tap = await p.page.evaluate(() => document.body.dataset.tap);
    assert.match(tap, /^[\d.]+,[\d.]+$/);
    assert.match(await p.page.textContent('#facts'), /where you tapped/);
    await screenshot(p.page, '7-result-sun-tapped');
    const hdr = await download(p.page, '#save-hdr');

    const out = path.join(synth, 'cli.hdr');
    cli(['merge', ...frames, '--times-file', path.join(synth, 'times.txt'), '--fisheye', '--lens-model', 'stereographic',
      '--fov', '235', '--crop', '--north', String(heading), '--sun', tap, '-o', out, '--quiet']);
    const expected = readFileSync(out);
    const pick = (lines, key) => lines.filter((l) => l.startsWith(key));
    const ours = headerLines(hdr.bytes);
    const theirs = headerLines(expected);
    assert.equal(pick(ours, '#SUN=').length, 1, ours.join('\n'));
    assert.equal(pick(ours, '#NORTH=').length, 1, ours.join('\n'));
    assert.deepEqual(pick(ours, '#SUN='), pick(theirs, '#SUN='));
    assert.deepEqual(pick(ours, '#NORTH='), pick(theirs, '#NORTH='));
    // The direction comment prints full f64 precision; wasm's and glibc's trigonometry may
    // differ in the last bit there, so its numbers are compared to 1e-9 degrees.
    const nums = (lines) => pick(lines, '#SUN_DIRECTION=').join(' ').match(/-?\d+\.?\d*(e-?\d+)?/g).map(Number);
    const [a, b] = [nums(ours), nums(theirs)];
    assert.equal(a.length, b.length);
    a.forEach((v, i) => assert.ok(Math.abs(v - b[i]) < 1e-9, `${v} vs ${b[i]}`));
    const body = (bytes) => bytes.subarray(bytes.indexOf('\n\n') + 2);
    assert.ok(body(hdr.bytes).equals(body(expected)), 'pixel data byte-identical to the CLI\'s');
    assert.deepEqual(ours.filter((l) => !l.startsWith('#SUN_DIRECTION=')), theirs.filter((l) => !l.startsWith('#SUN_DIRECTION=')));
    assertStayedHome(p);
  } finally { await p.close(); }
});

/** The `#NORTH=` point of a Radiance file's header as {x, y}. */
function northOf(bytes) {
  const line = headerLines(bytes).find((l) => l.startsWith('#NORTH='));
  assert.ok(line, 'a #NORTH= line');
  const m = line.match(/^#NORTH=-Y (\S+) \+X (\S+)$/);
  return { x: Number(m[2]), y: Number(m[1]) };
}

test('live overlay: the north point for a stored lens and the compass is the core\'s, where skydome merge puts #NORTH', async () => {
  const dir = tempDir('north');
  const demo = path.join(root, 'demo');
  const frames = ['frame_0.jpg', 'frame_1.jpg', 'frame_2.jpg'].map((f) => path.join(demo, f));
  const lensFile = path.join(dir, 'lens.json');
  cli(['lens', 'fit', '--circle', '200,200,192', '--fov', '235', '--model', 'stereographic', '-o', lensFile, '--quiet']);
  // The command line's north point for the same lens (no crop: the photo's own pixels, as the
  // live picture's) at each heading.
  const expected = (heading) => {
    const out = path.join(dir, `north_${heading}.hdr`);
    cli(['merge', ...frames, '--times-file', path.join(demo, 'times.txt'), '--lens', lensFile,
      '--north', String(heading), '-o', out, '--quiet']);
    return northOf(readFileSync(out));
  };
  const badFile = path.join(dir, 'bent_lens.json');
  const lens = JSON.parse(readFileSync(lensFile, 'utf8'));
  writeFileSync(badFile, JSON.stringify({ ...lens, circle: { ...lens.circle, r: -5 } }));

  const p = await phone(server.origin);
  try {
    await p.page.goto('about:blank');
    await setHeading(p.page, 37);
    await openApp(p);
    await compassAt(p.page, 37);
    // A profile the core refuses: its sentence names the file.
    await p.page.click('#to-settings');
    await onScreen(p.page, 'settings');
    await p.page.setInputFiles('#import', badFile);
    await p.page.waitForFunction(() => !document.getElementById('message').hidden);
    const refused = await p.page.textContent('#message');
    oneSentence(refused);
    assert.match(refused, /^bent_lens\.json: not a usable lens profile: /, refused);
    // The lens profile the command line wrote: the overlay is drawn for it.
    await p.page.setInputFiles('#import', lensFile);
    await p.page.waitForFunction(() => document.getElementById('message').className === 'info');
    await p.page.click('#settings-done');
    await onScreen(p.page, 'camera');
    for (const heading of [37, 200]) {
      await compassAt(p.page, heading);
      const want = expected(heading);
      await p.page.waitForFunction((w) => {
        const n = document.body.dataset.north;
        if (!n) return false;
        const [x, y] = n.split(',').map(Number);
        return Math.abs(x - w.x) < 1e-9 && Math.abs(y - w.y) < 1e-9;
      }, want, { timeout: 10000 }).catch(async () => {
        assert.fail(`north point ${await p.page.evaluate(() => document.body.dataset.north)} for heading ${heading}, the CLI's ${JSON.stringify(want)}`);
      });
    }
    await screenshot(p.page, '9-camera-north');
    assertStayedHome(p);
  } finally { await p.close(); }
});

test('offline: after the first visit the app loads and merges with the network cut', async () => {
  const demo = path.join(root, 'demo');
  const p = await phone(server.origin);
  try {
    await openApp(p);
    await p.context.setOffline(true);
    await p.page.reload();
    await onScreen(p.page, 'camera');
    await setSettings(p.page, { fisheye: true, sun: 'auto', north: '90' });
    const since = await pickFiles(p.page, ['frame_0.jpg', 'frame_1.jpg', 'frame_2.jpg', 'times.txt'].map((f) => path.join(demo, f)));
    const msg = await resultOrError(p.page, since);
    assert.equal(msg, null, `no error offline: ${msg}`);
    const hdr = await download(p.page, '#save-hdr');
    assert.ok(hdr.bytes.subarray(0, 10).toString('latin1').startsWith('#?RADIANCE'));
    assert.ok(headerLines(hdr.bytes).some((l) => l.startsWith('#NORTH=')));
    await p.context.setOffline(false);
    assertStayedHome(p);
  } finally { await p.close(); }
});

test('a broken photo gives the command line\'s error as one sentence naming the file', async () => {
  const dir = tempDir('broken');
  const a = path.join(dir, 'sky_a.jpg');
  const b = path.join(dir, 'sky_b.jpg');
  writeFileSync(a, Buffer.from([0xff, 0xd8, 0xff, 0xe0, 0, 16, 1, 2, 3]));
  writeFileSync(b, readFileSync(path.join(root, 'demo', 'frame_0.jpg')));
  // Their exposure times come with them (photos without EXIF times get the times form
  // otherwise, before anything is decoded; newuser.test.mjs).
  const list = path.join(dir, 'times.txt');
  writeFileSync(list, 'sky_a.jpg 1/250\nsky_b.jpg 1/60\n');
  const p = await phone(server.origin);
  try {
    await openApp(p);
    // First and second: with a decoding worker (two cores or more) the second photo is its.
    for (const names of [['sky_a.jpg', 'sky_b.jpg'], ['sky_b.jpg', 'sky_a.jpg']]) {
      const since = await pickFiles(p.page, [...names.map((n) => path.join(dir, n)), list]);
      const msg = await resultOrError(p.page, since);
      oneSentence(msg);
      assert.match(msg, /sky_a\.jpg/);
      // The core's message, as `skydome merge` prints it (`error: ` and the full stop aside).
      const line = cliError(['merge', ...names, '--times-file', 'times.txt', '-o', 'out.hdr'], dir).replace(/^error: /, '');
      assert.equal(msg.replace(/\.$/, ''), line.replace(/\.$/, ''));
    }
    await screenshot(p.page, '8-error');
    assertStayedHome(p);
  } finally { await p.close(); }
});

test('a decoding worker that cannot start: the merging worker decodes its photos, same bytes', async () => {
  // The built app with a decoder.js that throws as it loads, served on its own.
  const broken = tempDir('broken-decoder');
  cpSync(appDir, broken, { recursive: true });
  writeFileSync(path.join(broken, 'decoder.js'), "throw new Error('this decoding worker is broken on purpose');\n");
  const own = await serve(broken);
  const demo = path.join(root, 'demo');
  const frames = ['frame_0.jpg', 'frame_1.jpg', 'frame_2.jpg'].map((f) => path.join(demo, f));
  const out = tempDir('broken-decoder-cli');
  cli(['merge', ...frames, '--times-file', path.join(demo, 'times.txt'), '-o', path.join(out, 'cli.hdr'), '--quiet']);
  const expected = readFileSync(path.join(out, 'cli.hdr'));
  const p = await phone(own.origin);
  try {
    await p.page.goto(`${own.origin}/`, { waitUntil: 'domcontentloaded' });
    await onScreen(p.page, 'camera');
    await setSettings(p.page, { fisheye: false });
    const since = await pickFiles(p.page, [...frames, path.join(demo, 'times.txt')]);
    const msg = await resultOrError(p.page, since);
    assert.equal(msg, null, `no error: ${msg}`);
    await onScreen(p.page, 'result');
    const hdr = await download(p.page, '#save-hdr');
    assert.ok(hdr.bytes.equals(expected), 'byte-identical to skydome merge');
    assertStayedHome(p);
  } finally {
    await p.close();
    own.stop();
  }
});
