// The skydome phone app: screens, camera, compass, profiles and saving. No image processing
// happens here: every pixel is handled by skydome::pipeline in the worker (worker.js).
import * as camera from './camera.js';
import * as compass from './compass.js';
import * as profiles from './profiles.js';

const $ = (id) => document.getElementById(id);
const screens = ['camera', 'work', 'result', 'settings'];

// ---------------------------------------------------------------------------------------------
// Messages: one human sentence, never a stack trace. The core makes the sentences
// (skydome_web::sentence): the worker's errors and the report's warnings arrive made, any other
// error's message is sent to the worker to be made, and texts this page writes are sentences.

/** An error whose message is a finished sentence. */
class Sentence extends Error {}

/** Cancelling a run (the Cancel button says so itself). */
const cancelled = new Sentence('Cancelled: nothing was saved.');

/** The sentence for `err`; never rejects. */
async function sentenceOf(err) {
  if (err instanceof Sentence) return err.message;
  const text = String(err && err.message ? err.message : err);
  try {
    return await ask('sentence', { text });
  } catch (e) {
    // A worker that cannot answer says why in a sentence of its own.
    return e instanceof Sentence ? e.message : text;
  }
}

async function showError(err) {
  const text = await sentenceOf(err);
  const m = $('message');
  m.textContent = text;
  m.className = '';
  m.hidden = false;
}

function showInfo(text) {
  const m = $('message');
  m.textContent = text;
  m.className = 'info';
  m.hidden = false;
}

function clearMessage() { $('message').hidden = true; }

function show(name) {
  for (const s of screens) $(`screen-${s}`).hidden = s !== name;
  document.body.dataset.screen = name;
  // The camera runs only on its own screen: during a merge its frame buffers would share the
  // phone's memory with the core.
  if (name === 'camera' && !camera.running() && cameraWanted) startCamera();
  if (name === 'camera') updateMarks();
  if (name === 'work' && camera.running()) camera.stop();
}

// ---------------------------------------------------------------------------------------------
// The worker: one request at a time per id; cancelling terminates it (the core runs
// synchronously inside the worker, so a message could not reach it before it finishes).

let worker = null;
let nextId = 1;
const pending = new Map();

function startWorker() {
  worker = new Worker(new URL('./worker.js', import.meta.url), { type: 'module' });
  worker.onmessage = (e) => {
    const { id, progress, result, error } = e.data;
    const p = pending.get(id);
    if (!p) return;
    if (progress) { p.onProgress && p.onProgress(progress); return; }
    pending.delete(id);
    if (error) p.reject(new Sentence(error)); else p.resolve(result);
  };
  worker.onerror = (e) => {
    e.preventDefault();
    for (const p of pending.values()) p.reject(new Sentence('The processing stopped unexpectedly (the phone may be out of memory); try fewer or smaller photos.'));
    pending.clear();
    startWorker();
  };
}

function ask(type, payload = {}, onProgress = null, transfer = []) {
  const id = nextId++;
  return new Promise((resolve, reject) => {
    pending.set(id, { resolve, reject, onProgress });
    worker.postMessage({ id, type, ...payload }, transfer);
  });
}

function cancelWork() {
  worker.terminate();
  for (const p of pending.values()) p.reject(cancelled);
  pending.clear();
  startWorker();
}

// ---------------------------------------------------------------------------------------------
// Settings (localStorage) and the pipeline's Options (snake_case JSON, see skydome::pipeline).

const defaults = {
  fisheye: true, model: 'stereographic', fov: 235, iso: 200, shots: 3, spacing: 2,
  calibrate: false, sun: 'auto', north: '', location: false, equirect: false,
};

function loadSettings() {
  try { return { ...defaults, ...JSON.parse(localStorage.getItem('skydome.settings') || '{}') }; } catch { return { ...defaults }; }
}

function readForm() {
  const f = $('settings-form');
  const s = {};
  for (const [k, v] of Object.entries(defaults)) {
    const el = f.elements[k];
    if (typeof v === 'boolean') s[k] = el.checked;
    else if (typeof v === 'number') s[k] = Number(el.value);
    else s[k] = el.value;
  }
  return s;
}

function writeForm(s) {
  const f = $('settings-form');
  for (const [k, v] of Object.entries(s)) {
    const el = f.elements[k];
    if (!el) continue;
    if (typeof defaults[k] === 'boolean') el.checked = v; else el.value = v;
  }
}

let settings = loadSettings();

function saveSettings() {
  settings = readForm();
  localStorage.setItem('skydome.settings', JSON.stringify(settings));
}

/** The north heading used for a run: the one typed in Settings, else the compass. */
function northHeading() {
  if (settings.north !== '' && Number.isFinite(Number(settings.north))) return Number(settings.north);
  return compass.current();
}

let place = null; // {latitude_deg, longitude_deg} when the user allowed location

async function buildOptions({ tap = null, time = null } = {}) {
  const o = { products: { preview: true } };
  const cam = settings.calibrate ? null : await profiles.active('camera');
  // Without a stored profile the default response source applies: calibrate on this bracket.
  if (cam) o.response = { profile: JSON.parse(cam.json) };
  if (settings.fisheye) {
    const lens = await profiles.active('lens');
    o.lens = lens
      ? { profile: JSON.parse(lens.json) }
      : { detect: { model: settings.model, fov_deg: settings.fov, circle: null } };
    const north = northHeading();
    o.sky = {
      crop: true,
      fov_out_deg: 180,
      north_deg: north == null ? null : north,
      pose: 'screen_down',
      sun: tap ? { tap } : settings.sun,
      time,
    };
    if (place) Object.assign(o.sky, place);
    // The overlay picture is not made here: nothing on screen shows it, and the worker makes it
    // on request (a whole tone map of the dome less per merge).
    if (settings.equirect) o.products.equirect = {};
  }
  return o;
}

// ---------------------------------------------------------------------------------------------
// Running the pipeline.

let lastRun = null; // {options, times, result}

/** The work screen for a new run; returns its progress handler. The core's events carry the
 *  stage's name, its fraction and the run's (skydome_web::StageProgress: the stages' order is
 *  the core's); the bar never moves back within a run. */
function startWork(title, text) {
  show('work');
  $('work-title').textContent = title;
  $('progress').value = 0;
  $('stage').textContent = text;
  return (p) => {
    $('progress').value = Math.max($('progress').value, p.overall);
    $('stage').textContent = `${p.stage} ${Math.round(p.fraction * 100)} %`;
  };
}

async function merge(frames, times, optionExtras = {}) {
  clearMessage();
  const onProgress = startWork('Merging', 'sending the photos to the core');
  try {
    if (settings.location && !place) place = await locate().catch(() => null);
    const options = await buildOptions(optionExtras);
    const payload = { frames, options: JSON.stringify(options), times };
    const transfer = frames.map((f) => f.bytes);
    const result = await ask('run', payload, onProgress, transfer);
    lastRun = { options, times, result };
    await afterRun(result);
  } catch (err) {
    if (err === cancelled) return;
    show('camera');
    await showError(err);
  }
}

async function rerunWithTap(tap) {
  const onProgress = startWork('Marking the sun', 'starting');
  try {
    const options = await buildOptions({ tap, time: lastRun.options.sky ? lastRun.options.sky.time : null });
    const result = await ask('rerun', { options: JSON.stringify(options), times: lastRun.times }, onProgress);
    lastRun = { options, times: lastRun.times, result };
    await afterRun(result);
  } catch (err) {
    if (err === cancelled) return;
    show('result');
    await showError(err);
  }
}

async function afterRun(result) {
  // Keep what the core learned: the camera profile (first calibration) and the lens.
  if (result.camera_profile) {
    const prof = JSON.parse(result.camera_profile);
    const name = [prof.make, prof.model].filter(Boolean).join(' ') || 'this phone\'s camera';
    const stored = await profiles.list();
    const hasActive = stored.some((p) => p.kind === 'camera' && p.active);
    const known = stored.some((p) => p.kind === 'camera' && p.name === name);
    // Stored the first time a camera is calibrated, or when a new calibration was asked for.
    if (!known || settings.calibrate) {
      await profiles.save('camera', name, result.camera_profile, (!hasActive && lastRunSource === 'camera') || settings.calibrate);
    }
    if (settings.calibrate) { settings.calibrate = false; writeForm(settings); saveSettings(); }
  }
  if (result.lens_profile && !(await profiles.list()).some((p) => p.kind === 'lens')) {
    await profiles.save('lens', `${settings.model} ${settings.fov}°`, result.lens_profile, lastRunSource === 'camera');
  }
  const jpg = await ask('product', { name: 'preview' });
  const img = $('preview');
  if (img.src) URL.revokeObjectURL(img.src);
  img.src = URL.createObjectURL(new Blob([jpg.bytes], { type: 'image/jpeg' }));
  img.dataset.width = result.width;
  img.dataset.height = result.height;
  showFacts(result);
  show('result');
  window.__skydomeCoreMs = result.ms; // read by web-tests/measure.mjs
  window.__skydomeStageMs = result.stages;
  document.body.dataset.ready = String(Date.now());
}

function fmt(v, d = 1) { return v == null ? '—' : Number(v).toFixed(d); }

function showFacts(result) {
  const r = result.report;
  const facts = [];
  facts.push(['Size', `${r.width} × ${r.height} px`]);
  facts.push(['Frames', r.frames.map((f) => (f.time_s < 1 ? `1/${Math.round(1 / f.time_s)}` : `${f.time_s}`) + ' s').join(', ')]);
  facts.push(['Response', r.response]);
  const g = r.geometry;
  const sunMark = $('sun-mark');
  sunMark.hidden = true;
  if (g) {
    if (g.sun) {
      const s = g.sun;
      const dir = s.azimuth_deg != null ? `azimuth ${fmt(s.azimuth_deg, 2)}°, elevation ${fmt(s.elevation_deg, 2)}°` : `elevation ${fmt(s.elevation_deg, 2)}°`;
      facts.push(['Sun', `${g.sun_source}: (${fmt(s.pixel.x)}, ${fmt(s.pixel.y)}) ${dir}`]);
      sunMark.style.left = `${(100 * s.pixel.x) / r.width}%`;
      sunMark.style.top = `${(100 * s.pixel.y) / r.height}%`;
      sunMark.hidden = false;
    } else {
      facts.push(['Sun', 'none found: double-tap it']);
    }
    facts.push(['North', g.north ? `(${fmt(g.north.x)}, ${fmt(g.north.y)}), heading ${fmt(lastRun.options.sky.north_deg)}°` : 'unknown (no compass)']);
    if (g.sun_ephemeris) {
      facts.push(['Sun (ephemeris)', `azimuth ${fmt(g.sun_ephemeris.azimuth_deg, 2)}°, elevation ${fmt(g.sun_ephemeris.elevation_deg, 2)}°`]);
    }
    if (g.sun_disc) {
      // The core's reasons, in this page's words (skydome::sun_disc::DirectSource).
      const from = {
        measured_illuminance: 'the measured illuminance',
        model_direct_normal: 'the IES clear-sky model (±25 %)',
        model_ratio: 'the IES clear-sky model\'s direct/diffuse ratio (±25 %)',
      }[g.sun_disc.from] || g.sun_disc.from;
      const unit = g.sun_disc.absolute ? ' cd/m²' : ' (relative units)';
      facts.push(['Sun disc', `clipped in every photo: rebuilt at ${g.sun_disc.luminance.toExponential(2)}${unit} from ${from}`]);
    }
    if (g.sun_cross_check) {
      facts.push(['Cross-check', `${fmt(g.sun_cross_check.angle_deg, 2)}° apart; a compass error of ${fmt(g.sun_cross_check.compass_error_deg, 1)}° would explain it`]);
    }
  }
  facts.push(['Time in the core', `${(result.ms / 1000).toFixed(2)} s`]);
  const dl = $('facts');
  dl.replaceChildren();
  for (const [k, v] of facts) {
    const dt = document.createElement('dt'); dt.textContent = k;
    const dd = document.createElement('dd'); dd.textContent = v;
    dl.append(dt, dd);
  }
  const ul = $('warnings');
  ul.replaceChildren();
  for (const w of result.warnings) {
    const li = document.createElement('li'); li.textContent = w; ul.append(li);
  }
  $('save-equirect').hidden = !lastRun.options.products.equirect;
  $('tap-hint').hidden = !g;
  $('save-exr').hidden = false;
}

function locate() {
  return new Promise((resolve, reject) => {
    if (!navigator.geolocation) { reject(new Error('no location')); return; }
    navigator.geolocation.getCurrentPosition(
      (p) => resolve({ latitude_deg: p.coords.latitude, longitude_deg: p.coords.longitude }),
      reject, { enableHighAccuracy: false, timeout: 10000, maximumAge: 600000 },
    );
  });
}

// ---------------------------------------------------------------------------------------------
// Saving: downloads, or the Web Share API where the browser can share files.

const saves = {
  'save-hdr': { name: 'hdr', ext: 'hdr', type: 'image/vnd.radiance' },
  'save-jpg': { name: 'preview', ext: 'jpg', type: 'image/jpeg' },
  'save-exr': { name: 'exr', ext: 'exr', type: 'image/x-exr' },
  'save-equirect': { name: 'equirect', ext: 'hdr', type: 'image/vnd.radiance', suffix: '_latlong' },
};

function baseName() {
  const d = new Date();
  const p = (n) => String(n).padStart(2, '0');
  return `sky_${d.getFullYear()}${p(d.getMonth() + 1)}${p(d.getDate())}_${p(d.getHours())}${p(d.getMinutes())}${p(d.getSeconds())}`;
}

async function productFile(kind) {
  const s = saves[kind];
  const r = await ask('product', { name: s.name });
  return new File([r.bytes], `${baseName()}${s.suffix || ''}.${s.ext}`, { type: s.type });
}

async function save(kind) {
  clearMessage();
  try {
    const file = await productFile(kind);
    download(file);
  } catch (err) { showError(err); }
}

function download(file) {
  const a = document.createElement('a');
  a.href = URL.createObjectURL(file);
  a.download = file.name;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 60000);
}

async function share() {
  clearMessage();
  try {
    const files = [await productFile('save-hdr'), await productFile('save-jpg')];
    if (!navigator.canShare || !navigator.canShare({ files })) throw new Sentence('This browser cannot share files; use the Save buttons.');
    await navigator.share({ files, title: 'skydome sky' });
  } catch (err) {
    if (err && err.name === 'AbortError') return;
    showError(err);
  }
}

// ---------------------------------------------------------------------------------------------
// The preview: a double tap marks the sun. The tap is turned into preview pixels (the picture
// is shown scaled), and the core maps preview pixels to the input photo's pixels (the crop).

function previewPixel(ev) {
  const img = $('preview');
  const rect = img.getBoundingClientRect();
  const pt = ev.changedTouches ? ev.changedTouches[0] : ev;
  const x = ((pt.clientX - rect.left) / rect.width) * Number(img.dataset.width);
  const y = ((pt.clientY - rect.top) / rect.height) * Number(img.dataset.height);
  return { x, y };
}

let lastTap = 0;
let lastTouchDouble = 0;
async function onPreviewTap(ev) {
  const now = ev.timeStamp;
  // A touch double tap may be followed by a synthesised dblclick: count it once.
  if (ev.type === 'dblclick' && now - lastTouchDouble < 800) return;
  const isDouble = ev.type === 'dblclick' || now - lastTap < 350;
  lastTap = ev.type === 'dblclick' ? 0 : now;
  if (!isDouble) return;
  if (ev.type === 'touchend') { lastTouchDouble = now; lastTap = 0; }
  ev.preventDefault();
  if (!lastRun || !lastRun.options.sky) {
    await showError(new Sentence('Marking the sun needs a fish-eye bracket (turn on the fish-eye lens in Settings).'));
    return;
  }
  let tap;
  try {
    const input = await ask('inputPixel', previewPixel(ev));
    // Tenths of a pixel: the same numbers a user would type as `skydome merge --sun X,Y`.
    tap = { x: Math.round(input.x * 10) / 10, y: Math.round(input.y * 10) / 10 };
  } catch (err) {
    await showError(err);
    return;
  }
  document.body.dataset.tap = `${tap.x},${tap.y}`;
  await rerunWithTap(tap);
}

// ---------------------------------------------------------------------------------------------
// The live camera and its overlay: the lens circle, the 180° horizon and the north point, in the
// camera picture's pixels, all three made by the core (skydome_web::live_marks), the north point
// for the current heading.

let lens = null;  // what the overlay is drawn for: {lens: a stored profile's JSON} or {circle: detected}, with model and fov
let marks = null; // the core's marks for `lens`: {circle, horizon, north (null without a heading), heading}
let lensRetry = null;

function drawOverlay() {
  const video = $('video');
  const canvas = $('overlay');
  const w = video.videoWidth || 3;
  const h = video.videoHeight || 4;
  if (canvas.width !== w) canvas.width = w;
  if (canvas.height !== h) canvas.height = h;
  const g = canvas.getContext('2d');
  g.clearRect(0, 0, w, h);
  const n = marks && marks.north;
  // The point drawn, for the browser tests.
  if (n) document.body.dataset.north = `${n.x},${n.y}`; else delete document.body.dataset.north;
  if (!marks) return;
  const lw = Math.max(3, w / 200);
  g.lineWidth = lw;
  g.strokeStyle = '#ffd400';
  g.beginPath(); g.arc(marks.circle.cx, marks.circle.cy, marks.circle.r, 0, 2 * Math.PI); g.stroke();
  g.setLineDash([4 * lw, 3 * lw]);
  g.strokeStyle = '#ffffff';
  g.beginPath(); g.arc(marks.horizon.cx, marks.horizon.cy, marks.horizon.r, 0, 2 * Math.PI); g.stroke();
  g.setLineDash([]);
  if (n) {
    g.fillStyle = '#1e6bff';
    g.strokeStyle = '#ffffff';
    g.beginPath(); g.arc(n.x, n.y, 4 * lw, 0, 2 * Math.PI); g.fill(); g.stroke();
    g.fillStyle = '#ffffff';
    g.font = `bold ${Math.round(10 * lw)}px system-ui, sans-serif`;
    g.fillText('N', n.x + 5 * lw, n.y - 5 * lw);
  }
}

/** The core's marks for lens `l` at the current heading. */
async function askMarks(l) {
  const heading = northHeading();
  return { ...(await ask('overlay', { ...l, heading })), heading };
}

// Keeps the north point on the current heading while the camera screen shows: one request at a
// time, and a heading that changed meanwhile is asked for when the answer arrives.
let marking = false;
async function updateMarks() {
  if (marking) return;
  marking = true;
  try {
    while (lens && marks && marks.heading !== northHeading() && document.body.dataset.screen === 'camera') {
      const l = lens;
      const m = await askMarks(l);
      if (l === lens) marks = m;
      drawOverlay();
    }
  } catch {
    // The same lens gave marks before: keep them (the worker was restarted, e.g. by a Cancel).
  } finally {
    marking = false;
  }
}

/** Forgets the overlay's lens (settings or profiles changed) and finds it again. */
function resetLens() {
  lens = null;
  marks = null;
  drawOverlay();
  findLens();
}

async function findLens() {
  let stored = null;
  try {
    stored = await profiles.active('lens');
    let l = null;
    if (stored) {
      l = { lens: stored.json, model: settings.model, fov: settings.fov };
    } else if (settings.fisheye) {
      const frame = await camera.grabFrame($('video'));
      if (!frame) return;
      const fit = await ask('circle', { name: 'camera picture', bytes: frame.bytes }, null, [frame.bytes]);
      l = { circle: fit.circle, model: settings.model, fov: settings.fov };
    }
    const m = l && (await askMarks(l));
    lens = l;
    marks = m;
    $('lens-status').textContent = m ? `Lens circle r ${m.circle.r.toFixed(0)} px, horizon r ${m.horizon.r.toFixed(0)} px${stored ? ' (stored lens profile)' : ' (detected)'}.` : '';
    $('lens-status').title = '';
  } catch (err) {
    lens = null;
    marks = null;
    // Not an error: the lens may simply not be on yet. The core's reason is kept for the curious.
    $('lens-status').textContent = 'No fish-eye circle in the camera picture yet: the overlay appears once the lens is on.';
    $('lens-status').title = await sentenceOf(err);
    if (!lensRetry) lensRetry = setTimeout(() => { lensRetry = null; if (document.body.dataset.screen === 'camera') findLens(); }, 5000);
  }
  drawOverlay();
  updateMarks();
}

let cameraWanted = false;

async function startCamera() {
  cameraWanted = true;
  try {
    await camera.start($('video'));
    const caps = camera.manualExposure();
    $('capture').disabled = false;
    $('camera-status').textContent = caps
      ? `Manual exposure ${caps.exposureTime.min / 10}–${caps.exposureTime.max / 10} ms available: lay the phone screen-down, camera up, and tap Capture.`
      : 'This browser offers no manual exposure for this camera: pick bracketed photos from the gallery instead.';
    $('video').addEventListener('loadeddata', () => setTimeout(findLens, 500), { once: true });
    if ($('video').readyState >= 2) setTimeout(findLens, 500);
  } catch (err) {
    const refused = err && err.name === 'NotAllowedError'
      ? new Sentence('The camera was not allowed; pick bracketed photos from the gallery instead.') : err;
    $('camera-status').textContent = camera.manualExposure() ? '' : await sentenceOf(refused);
  }
}

async function exifTime(blob, name) {
  try {
    const r = await ask('exposure', { name, bytes: await blob.arrayBuffer() });
    return r.exif_time_s;
  } catch { return null; }
}

async function capture() {
  clearMessage();
  $('capture').disabled = true;
  try {
    const heading = northHeading();
    const when = isoNow();
    const shot = await camera.captureBracket(
      { iso: settings.iso, shots: settings.shots, spacing: settings.spacing },
      exifTime,
      (t) => { $('camera-status').textContent = t; },
    );
    document.body.dataset.capture = JSON.stringify({ requested: shot.requested, readBack: shot.readBack, heading, time: when });
    const frames = [];
    for (const f of shot.frames) frames.push({ name: f.name, bytes: await f.blob.arrayBuffer() });
    lastRunSource = 'camera';
    await merge(frames, shot.frames.map((f) => f.time_s), { time: when });
  } catch (err) {
    await showError(err);
  } finally {
    $('capture').disabled = false;
  }
}

function isoNow() {
  const d = new Date();
  const p = (n) => String(Math.floor(Math.abs(n))).padStart(2, '0');
  const off = -d.getTimezoneOffset();
  return `${d.getFullYear()}-${p(d.getMonth() + 1)}-${p(d.getDate())}T${p(d.getHours())}:${p(d.getMinutes())}:${p(d.getSeconds())}${off >= 0 ? '+' : '-'}${p(off / 60)}:${p(off % 60)}`;
}

let lastRunSource = 'gallery';

async function fromGallery(ev) {
  const picked = [...ev.target.files];
  ev.target.value = '';
  if (picked.length === 0) return;
  clearMessage();
  // Photos without EXIF (e.g. from `skydome synth`) come with their list of times, the command
  // line's --times-file format, picked together with them.
  const lists = picked.filter((f) => /\.(txt|csv)$/i.test(f.name));
  const files = picked.filter((f) => !lists.includes(f));
  if (files.length < 2) {
    await showError(new Sentence('Pick at least two photos of the same sky at different exposures.'));
    return;
  }
  try {
    let times = [];
    if (lists.length > 0) {
      times = await ask('times', { listName: lists[0].name, text: await lists[0].text(), names: files.map((f) => f.name) });
    }
    const frames = [];
    for (const f of files) frames.push({ name: f.name, bytes: await f.arrayBuffer() });
    lastRunSource = 'gallery';
    await merge(frames, times);
  } catch (err) { await showError(err); }
}

// ---------------------------------------------------------------------------------------------
// Profiles screen: list, activate, export (download), import (checked by the core), delete.

async function renderProfiles() {
  const ul = $('profiles');
  ul.replaceChildren();
  const all = await profiles.list();
  if (all.length === 0) {
    const li = document.createElement('li');
    li.textContent = 'None yet: the first bracket calibrates the camera and stores its profile here.';
    ul.append(li);
  }
  for (const p of all) {
    const li = document.createElement('li');
    const title = document.createElement('div');
    title.textContent = `${p.kind === 'camera' ? 'Camera' : 'Lens'}: ${p.name}${p.active ? ' (in use)' : ''}`;
    const row = document.createElement('div');
    row.className = 'actions';
    const use = document.createElement('button');
    use.type = 'button';
    use.className = 'small';
    use.textContent = p.active ? 'Stop using' : 'Use';
    use.onclick = () => profiles.setActive(p.id, !p.active).then(() => { resetLens(); return renderProfiles(); }).catch(showError);
    const exp = document.createElement('button');
    exp.type = 'button';
    exp.className = 'small';
    exp.textContent = 'Export';
    exp.onclick = () => download(new File([p.json], `${p.kind}_${p.name.replace(/[^A-Za-z0-9._-]+/g, '_')}.json`, { type: 'application/json' }));
    const del = document.createElement('button');
    del.type = 'button';
    del.className = 'small';
    del.textContent = 'Delete';
    del.onclick = () => profiles.remove(p.id).then(() => { resetLens(); return renderProfiles(); }).catch(showError);
    row.append(use, exp, del);
    li.append(title, row);
    ul.append(li);
  }
}

async function importProfile(ev) {
  const file = ev.target.files[0];
  ev.target.value = '';
  if (!file) return;
  clearMessage();
  try {
    const text = await file.text();
    const kind = profiles.kindOf(text);
    if (!kind) throw new Sentence(`${file.name} is neither a skydome camera profile nor a lens profile.`);
    // The core's check names the file in its message.
    const json = await ask(kind === 'camera' ? 'checkCamera' : 'checkLens', { name: file.name, json: text });
    await profiles.save(kind, file.name.replace(/\.json$/i, ''), json, true);
    showInfo(`Imported ${file.name}; it is now in use.`);
    await renderProfiles();
    if (kind === 'lens') resetLens();
  } catch (err) {
    await showError(err);
  }
}

// ---------------------------------------------------------------------------------------------

function wire() {
  writeForm(settings);
  $('settings-form').addEventListener('change', () => { saveSettings(); resetLens(); });
  $('to-settings').onclick = () => { show('settings'); renderProfiles().catch(showError); };
  $('settings-done').onclick = () => { saveSettings(); show('camera'); };
  $('gallery').addEventListener('change', fromGallery);
  $('capture').onclick = capture;
  $('cancel').onclick = () => { cancelWork(); show('camera'); showInfo('Cancelled: nothing was saved.'); };
  $('back').onclick = () => { clearMessage(); show('camera'); };
  for (const id of Object.keys(saves)) $(id).onclick = () => save(id);
  $('share').hidden = !(navigator.canShare && navigator.canShare({ files: [new File([''], 'x.hdr')] }));
  $('share').onclick = share;
  $('import').addEventListener('change', importProfile);
  const img = $('preview');
  img.addEventListener('dblclick', onPreviewTap);
  img.addEventListener('touchend', onPreviewTap);
  compass.start((h) => {
    $('heading').textContent = `${h.toFixed(1)}° (top edge)`;
    $('compass-permission').hidden = true;
    updateMarks();
  }, () => {
    const b = $('compass-permission');
    b.hidden = false;
    b.onclick = () => compass.requestPermission().then(() => { b.hidden = true; }).catch(showError);
  });
}

startWorker();
window.__skydomeAsk = ask; // for web-tests/measure.mjs (the worker's memory)
wire();
show('camera');
startCamera();
if ('serviceWorker' in navigator) {
  navigator.serviceWorker.register('sw.js').catch(() => {});
}
