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

/** An error whose message is a finished sentence; `kind` is the core's name for it
 *  (skydome_web::WebError::kind: 'no-circle', 'missing-times', …), when it has one. */
class Sentence extends Error {
  constructor(message, kind = null) { super(message); this.kind = kind; }
}

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
  // A cancelled run says so itself (the Cancel button's notice); requests it cut short are not
  // errors.
  if (err === cancelled) return;
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

let squeezedAnswer = null; // answers the pending question of acceptSqueezed

function clearMessage() {
  $('message').hidden = true;
  $('no-circle').hidden = true;
  // A squeezed bracket left unanswered (the user went on to something else) is not merged.
  if (squeezedAnswer) squeezedAnswer(false);
  $('squeezed').hidden = true;
}

function show(name) {
  for (const s of screens) $(`screen-${s}`).hidden = s !== name;
  document.body.dataset.screen = name;
  // Settings cannot change under a running merge; the header button shows where you are.
  $('to-settings').disabled = name === 'work';
  $('to-settings').setAttribute('aria-pressed', String(name === 'settings'));
  // The camera runs only on its own screen: during a merge its frame buffers would share the
  // phone's memory with the core.
  if (name === 'camera' && !camera.running() && cameraWanted) startCamera();
  // The overlay's line widths depend on the viewfinder's size on screen (none while hidden).
  if (name === 'camera') { drawOverlay(); updateMarks(); }
  if (name === 'work' && camera.running()) camera.stop();
}

// ---------------------------------------------------------------------------------------------
// The worker: one request at a time per id; cancelling terminates it (the core runs
// synchronously inside the worker, so a message could not reach it before it finishes).

let worker = null;
let nextId = 1;
const pending = new Map();

// `?threads=N` on the page's URL sets the threaded core's pool size (0: the single-threaded
// core); without it the worker picks (one thread per core, when the page is isolated).
const threadsAsked = new URLSearchParams(location.search).get('threads');
// `?memory=MiB` sets the budget for a bracket's photos decoded at once (the worker's default:
// 256 MiB; above it the core reads them one at a time).
const memoryAsked = new URLSearchParams(location.search).get('memory');
// `?reserve=MiB` sets how much memory the core reserves while idle for the first merge (the
// worker's default: 160 MiB; 0: none).
const reserveAsked = new URLSearchParams(location.search).get('reserve');
const pageQuery = new URLSearchParams(location.search);

function startWorker() {
  const url = new URL('./worker.js', import.meta.url);
  if (threadsAsked != null) url.searchParams.set('threads', threadsAsked);
  if (memoryAsked != null) url.searchParams.set('memory', memoryAsked);
  if (reserveAsked != null) url.searchParams.set('reserve', reserveAsked);
  // The idle warm-up's knobs (worker.js): ?warmup=N 256² merges, ?stages=N rounds of the
  // stages warm-up, ?stageside=N its pictures' side.
  for (const name of ['warmup', 'stages', 'stageside']) {
    const v = pageQuery.get(name);
    if (v != null) url.searchParams.set(name, v);
  }
  worker = new Worker(url, { type: 'module' });
  worker.onmessage = (e) => {
    const { id, progress, result, error, kind } = e.data;
    const p = pending.get(id);
    if (!p) return;
    if (progress) { p.onProgress && p.onProgress(progress); return; }
    pending.delete(id);
    if (error) p.reject(new Sentence(error, kind)); else p.resolve(result);
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

async function buildOptions({ tap = null, time = null, reference = null, plain = false, circle = null } = {}) {
  const o = { products: { preview: true } };
  if (reference) o.reference = reference;
  // `plain`: these photos as ordinary (rectangular) ones, whatever the fish-eye setting.
  if (plain) return o;
  const cam = settings.calibrate ? null : await profiles.active('camera');
  // Without a stored profile the default response source applies: calibrate on this bracket.
  if (cam) o.response = { profile: JSON.parse(cam.json) };
  if (settings.fisheye) {
    const lens = await profiles.active('lens');
    o.lens = lens
      ? { profile: JSON.parse(lens.json) }
      : { detect: { model: settings.model, fov_deg: settings.fov, circle } };
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
const STAGE_LABELS = {
  decoding: 'Reading the photos',
  lens: 'Finding the lens circle',
  calibrating: 'Calibrating the camera',
  merging: 'Merging the exposures',
  sky: 'Placing the sun and north',
  pictures: 'Making the preview',
};
let workToken = 0;

function startWork(title, text) {
  // The bar starts empty before the screen shows, and only this run's events move it.
  const token = ++workToken;
  $('progress').value = 0;
  $('stage').textContent = text;
  $('work-title').textContent = title;
  show('work');
  return (p) => {
    if (token !== workToken) return;
    $('progress').value = Math.max($('progress').value, p.overall);
    const label = STAGE_LABELS[p.stage] || p.stage;
    $('stage').textContent = `${label}… ${Math.round(p.overall * 100)} %`;
  };
}

/** The core's refusal of identical photos, in the words that fit a bracket captured here: the
 *  camera reported the times asked for, so its exposure setting is not to blame. */
function capturedRefusal(err) {
  const text = String(err && err.message ? err.message : err);
  // The core names every photo of each group of identical ones: "A, B and C: pixels are …"
  // (groups separated by "; ").
  const m = text.match(/^(.+?): pixels are nearly identical although/i);
  if (!m) return err;
  const names = m[1].replace(/\.jpg/gi, '');
  if (!/^photo \d+ of \d+((, | and |; )photo \d+ of \d+)*$/i.test(names)) return err;
  return new Sentence(`P${names.slice(1)} came out nearly identical although the camera reported the exposure times asked for, so this browser cannot bracket with it: take the bracket with the camera app and merge it with Pick photos.`);
}

async function merge(frames, times, optionExtras = {}, { honoured = false } = {}) {
  clearMessage();
  const onProgress = startWork('Merging', 'Handing the photos over…');
  try {
    if (settings.location && !place) place = await locate().catch(() => null);
    const options = await buildOptions(optionExtras);
    // One photo stays here (a copy), to drag the lens circle on if none is found; the worker
    // keeps them all for another try.
    const mid = frames[Math.floor(frames.length / 2)];
    circlePhoto = mid ? new Blob([mid.bytes.slice(0)], { type: 'image/jpeg' }) : null;
    const payload = { frames, options: JSON.stringify(options), times };
    const transfer = frames.map((f) => f.bytes);
    const result = await ask('run', payload, onProgress, transfer);
    lastRun = { options, times, result, name: frames.length ? frames[0].name : null };
    await afterRun(result);
  } catch (err) {
    if (err === cancelled) return;
    show('camera');
    await showError(honoured ? capturedRefusal(err) : err);
    if (err.kind === 'no-circle') offerNoCircle(times, optionExtras);
  }
}

let circlePhoto = null; // a photo of the last bracket, to drag the lens circle on

/** Merges the photos the worker holds again, with other options (a retry after a refusal). */
async function mergeAgain(times, optionExtras) {
  clearMessage();
  const onProgress = startWork('Merging', 'Starting…');
  try {
    const options = await buildOptions(optionExtras);
    const result = await ask('rerun', { options: JSON.stringify(options), times }, onProgress);
    lastRun = { options, times, result, name: lastRun ? lastRun.name : null };
    await afterRun(result);
  } catch (err) {
    if (err === cancelled) return;
    show('camera');
    await showError(err);
    if (err.kind === 'no-circle') offerNoCircle(times, optionExtras);
  }
}

/** No fish-eye circle: offer the ordinary (rectangular) path for these photos, and giving the
 *  circle by hand (dragging it on the photo). */
function offerNoCircle(times, optionExtras) {
  const box = $('no-circle');
  box.hidden = false;
  $('no-circle-drag').hidden = !circlePhoto;
  $('no-circle-plain').onclick = () => { box.hidden = true; mergeAgain(times, { ...optionExtras, plain: true }); };
  $('no-circle-drag').onclick = () => { box.hidden = true; editCircle(times, optionExtras); };
  box.scrollIntoView({ block: 'nearest' });
}

/** The circle editor: the photo with a circle to drag (centre) and size (slider), in the
 *  photo's pixels; "Use this circle" merges with it as the lens circle. */
async function editCircle(times, optionExtras) {
  const img = $('circle-photo');
  if (img.src) URL.revokeObjectURL(img.src);
  img.src = URL.createObjectURL(circlePhoto);
  await img.decode();
  const w = img.naturalWidth;
  const h = img.naturalHeight;
  const c = { cx: w / 2, cy: h / 2, r: Math.min(w, h) / 2 };
  const svg = $('circle-svg');
  svg.setAttribute('viewBox', `0 0 ${w} ${h}`);
  const ring = $('circle-ring');
  const slider = $('circle-r');
  slider.min = String(Math.round(Math.min(w, h) / 10));
  slider.max = String(Math.round(Math.max(w, h) * 0.75));
  slider.value = String(Math.round(c.r));
  const draw = () => {
    ring.setAttribute('cx', c.cx); ring.setAttribute('cy', c.cy); ring.setAttribute('r', c.r);
    ring.setAttribute('stroke-width', String(Math.max(2, w / 150)));
    // The circle as it will be used (tenths of a pixel), for the browser tests.
    document.body.dataset.circle = [c.cx, c.cy, c.r].map((v) => Math.round(v * 10) / 10).join(',');
  };
  draw();
  const toPhoto = (ev) => {
    const rect = svg.getBoundingClientRect();
    return { x: ((ev.clientX - rect.left) / rect.width) * w, y: ((ev.clientY - rect.top) / rect.height) * h };
  };
  let dragging = false;
  svg.onpointerdown = (ev) => { dragging = true; svg.setPointerCapture(ev.pointerId); const p = toPhoto(ev); c.cx = p.x; c.cy = p.y; draw(); };
  svg.onpointermove = (ev) => { if (!dragging) return; const p = toPhoto(ev); c.cx = p.x; c.cy = p.y; draw(); };
  svg.onpointerup = () => { dragging = false; };
  slider.oninput = () => { c.r = Number(slider.value); draw(); };
  $('circle-use').onclick = () => {
    $('circle-editor').hidden = true;
    const circle = { cx: Math.round(c.cx * 10) / 10, cy: Math.round(c.cy * 10) / 10, r: Math.round(c.r * 10) / 10 };
    mergeAgain(times, { ...optionExtras, circle });
  };
  $('circle-cancel').onclick = () => { $('circle-editor').hidden = true; };
  $('circle-editor').hidden = false;
  $('circle-editor').scrollIntoView({ block: 'start' });
}

/** The sun tapped in the last run, if it was tapped. */
function tappedSun() {
  const sky = lastRun && lastRun.options.sky;
  return sky && sky.sun && sky.sun.tap ? sky.sun.tap : null;
}

async function rerunWithTap(tap) { return rerun('Marking the sun', { tap, reference: lastRun.options.reference || null }); }

/** Merges the same photos again with a tapped sun and/or meter readings. */
async function rerun(title, { tap = tappedSun(), reference = null }) {
  const onProgress = startWork(title, 'Starting…');
  try {
    const options = await buildOptions({ tap, reference, time: lastRun.options.sky ? lastRun.options.sky.time : null });
    const result = await ask('rerun', { options: JSON.stringify(options), times: lastRun.times }, onProgress);
    lastRun = { ...lastRun, options, result };
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
    // Named after the camera that took the photos (EXIF); only a bracket captured here is
    // "this phone's camera".
    const name = [prof.make, prof.model].filter(Boolean).join(' ')
      || (lastRunSource === 'camera' ? 'this phone\'s camera' : `the camera of ${lastRun.name || 'the picked photos'}`);
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
  showView(false);
  const fc = $('false-colour');
  if (fc.src) URL.revokeObjectURL(fc.src);
  fc.removeAttribute('src');
  showFacts(result);
  showSpot();
  show('result');
  window.__skydomeCoreMs = result.ms; // read by web-tests/measure.mjs
  window.__skydomeStageMs = result.stages;
  window.__skydomeStageMemory = result.stageMemory;
  window.__skydomeCore = result.core;
  window.__skydomeStreamed = result.streamed === true; // whether the core read the photos one at a time
  document.body.dataset.ready = String(Date.now());
}

function fmt(v, d = 1) { return v == null ? '—' : Number(v).toFixed(d); }

/** A photometric figure with three significant digits (e.g. 12 300, 0.0451). */
function sig(v) {
  if (v == null || !Number.isFinite(v)) return '—';
  if (v === 0) return '0';
  const e = Math.floor(Math.log10(Math.abs(v)));
  const r = Number(v.toPrecision(3));
  return e >= 3 ? Math.round(r).toLocaleString('en-US').replace(/,/g, ' ') : String(r);
}

function showFacts(result) {
  const r = result.report;
  const facts = [];
  const lum = result.luminance;
  const absolute = !!(lum && lum.absolute);
  const photometry = r.photometry;
  facts.push(['Picture', `${r.width} × ${r.height} pixels`]);
  facts.push(['Photos', `${r.frames.length}, exposed ${r.frames.map((f) => (f.time_s < 1 ? `1/${Math.round(1 / f.time_s)}` : `${f.time_s}`) + ' s').join(', ')}`]);
  facts.push(['Camera response', r.response === 'profile' ? 'from the stored camera profile' : 'measured from these photos']);
  if (photometry && photometry.horizontal_illuminance_lux != null) {
    facts.push(['Horizontal illuminance', `${sig(photometry.horizontal_illuminance_lux)} lux: the light the whole sky puts on a level surface`]);
  } else if (!absolute) {
    facts.push(['Horizontal illuminance', 'needs a meter reading (Meter readings, below): the photos alone give relative values']);
  }
  if (photometry && photometry.disagreement_percent != null) {
    facts.push(['Meter agreement', `the lux reading and the spot reading disagree by ${fmt(photometry.disagreement_percent, 1)} %`]);
  }
  if (lum) {
    const unit = absolute ? ' cd/m²' : ' (relative units)';
    facts.push(['Sky luminance', `${sig(lum.p1)} to ${sig(lum.p999)}${unit} (1st to 99.9th percentile), median ${sig(lum.median)}, brightest ${sig(lum.max)}`]);
  }
  const g = r.geometry;
  const sunMark = $('sun-mark');
  sunMark.hidden = true;
  if (g) {
    if (g.sun) {
      const s = g.sun;
      const how = { detected: 'found in the picture', tap: 'where you tapped', ephemeris: 'from the date, time and place' }[g.sun_source] || g.sun_source;
      const dir = s.azimuth_deg != null ? `${fmt(s.azimuth_deg, 1)}° from north towards east, ${fmt(s.elevation_deg, 1)}° above the horizon` : `${fmt(s.elevation_deg, 1)}° above the horizon`;
      facts.push(['Sun', `${dir} (${how})`]);
      sunMark.style.left = `${(100 * s.pixel.x) / r.width}%`;
      sunMark.style.top = `${(100 * s.pixel.y) / r.height}%`;
      sunMark.hidden = false;
    } else {
      facts.push(['Sun', 'none found: double-tap it on the picture']);
      // A sun the lens setting misses: the usual cause is the projection or field of view.
      if (!lastRun.options.lens.profile) {
        facts.push(['Lens hint', `no sun was found with the ${lastRun.options.lens.detect.model} ${lastRun.options.lens.detect.fov_deg}° lens setting; if the sun is in the picture, the lens may be another kind (a 180° sky camera is usually equisolid 180°): change it in Settings and merge again`]);
      }
    }
    const north = lastRun.options.sky.north_deg;
    facts.push(['North', north != null ? `the phone's top edge pointed ${fmt(north, 1)}° from north` : 'unknown (no compass reading; type the heading in Settings)']);
    if (g.sun_disc) {
      const d = g.sun_disc;
      const from = {
        measured_illuminance: 'your lux reading',
        model_direct_normal: 'a clear-sky model (±25 %)',
        model_ratio: 'a clear-sky model\'s direct/diffuse ratio (±25 %)',
      }[d.from] || d.from;
      const u = d.absolute ? ' lux' : ' (relative)';
      facts.push(['Sun, direct and diffuse', `direct ${sig(d.direct_horizontal)}${u} and diffuse ${sig(d.diffuse_horizontal)}${u} on a level surface; the sun was too bright for every photo, so its disc was rebuilt from ${from}`]);
    }
    if (g.sun_ephemeris) {
      facts.push(['Sun from the date and place', `${fmt(g.sun_ephemeris.azimuth_deg, 1)}° from north, ${fmt(g.sun_ephemeris.elevation_deg, 1)}° up`]);
    }
    if (g.sun_cross_check) {
      facts.push(['Cross-check', `the sun in the picture is ${fmt(g.sun_cross_check.angle_deg, 1)}° from where the date, time and place put it; a compass off by ${fmt(g.sun_cross_check.compass_error_deg, 1)}° would explain that`]);
    } else if (settings.location && !place) {
      facts.push(['Cross-check', 'no location was given, so the sun found in the picture could not be checked against the date, time and place']);
    } else if (settings.location && !g.sun_ephemeris) {
      facts.push(['Cross-check', 'the photos carry no date and time, so the sun found in the picture could not be checked against where the date, time and place put it']);
    } else if (settings.location && !g.sun) {
      facts.push(['Cross-check', 'no sun was found in the picture to check against where the date, time and place put it']);
    }
  }
  const core = result.core || { threads: 1 };
  facts.push(['Time in the core', `${(result.ms / 1000).toFixed(2)} s on ${core.threads === 1 ? 'one thread' : `${core.threads} threads`}`]);
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
  $('view-toggle').textContent = absolute ? 'False colour, cd/m²' : 'False colour';
}

// ---------------------------------------------------------------------------------------------
// The false-colour view (the core's, as `skydome falsecolor` draws it) and meter readings.

/** Shows the false-colour view (true) or the picture (false). */
async function showView(falseColour) {
  const b = $('view-toggle');
  b.setAttribute('aria-pressed', String(falseColour));
  const fc = $('false-colour');
  if (falseColour && !fc.getAttribute('src')) {
    try {
      const r = await ask('product', { name: 'falsecolour' });
      fc.src = URL.createObjectURL(new Blob([r.bytes], { type: 'image/jpeg' }));
      await fc.decode().catch(() => {});
    } catch (err) { await showError(err); return; }
  }
  fc.hidden = !falseColour;
  $('preview').hidden = falseColour;
  $('sun-mark').hidden = falseColour || !(lastRun && lastRun.result.report.geometry && lastRun.result.report.geometry.sun);
  $('spot-mark').hidden = falseColour || !spot;
  document.body.dataset.view = falseColour ? 'false-colour' : 'picture';
}

let spot = null;       // the metered spot: {input: {x, y} (input-photo pixels), preview: {x, y}}
let markingSpot = false;

function showSpot() {
  const m = $('spot-mark');
  const img = $('preview');
  if (!spot) { m.hidden = true; return; }
  m.style.left = `${(100 * spot.preview.x) / Number(img.dataset.width)}%`;
  m.style.top = `${(100 * spot.preview.y) / Number(img.dataset.height)}%`;
  m.hidden = img.hidden;
  $('meter-spot-at').textContent = `Spot at pixel (${fmt(spot.input.x, 0)}, ${fmt(spot.input.y, 0)}) of the photos, averaged over ${SPOT_RADIUS_PX} pixels around it.`;
}

/** The metered patch's radius, input-photo pixels (a spot meter's 1° is a few pixels). */
const SPOT_RADIUS_PX = 5;

async function markSpot(ev) {
  markingSpot = false;
  $('meter-mark').setAttribute('aria-pressed', 'false');
  try {
    const pv = previewPixel(ev);
    const input = await ask('inputPixel', pv);
    spot = { input: { x: Math.round(input.x * 10) / 10, y: Math.round(input.y * 10) / 10 }, preview: pv };
    showSpot();
  } catch (err) { await showError(err); }
}

async function applyReadings() {
  clearMessage();
  const lux = $('meter-lux').value.trim();
  const cd = $('meter-cd').value.trim();
  const reference = {};
  if (lux !== '') {
    if (!(Number(lux) > 0)) { await showError(new Sentence('Type the illuminance as a positive number of lux.')); return; }
    reference.illuminance_lux = Number(lux);
  }
  if (cd !== '') {
    if (!(Number(cd) > 0)) { await showError(new Sentence('Type the spot luminance as a positive number of cd/m².')); return; }
    if (!spot) { await showError(new Sentence('Tap “Mark the spot” and then the place the meter pointed at, so the spot reading has a place.')); return; }
    reference.luminance = { pixel: spot.input, radius_px: SPOT_RADIUS_PX, cd_per_m2: Number(cd) };
  }
  if (!reference.illuminance_lux && !reference.luminance) {
    await showError(new Sentence('Type a lux reading, a spot luminance in cd/m², or both.'));
    return;
  }
  await rerun('Applying the readings', { reference });
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
  'save-false': { name: 'falsecolour', ext: 'jpg', type: 'image/jpeg', suffix: '_falsecolour' },
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
  const b = $(kind);
  const label = b.textContent;
  b.disabled = true;
  b.textContent = 'Saving…';
  try {
    const file = await productFile(kind);
    download(file);
    const mb = file.size / 2 ** 20;
    showInfo(`Saved ${file.name} (${mb >= 0.1 ? `${mb.toFixed(1)} MB` : `${Math.ceil(file.size / 1024)} KB`}) to this phone's downloads.`);
  } catch (err) {
    await showError(err);
  } finally {
    b.disabled = false;
    b.textContent = label;
  }
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
  if (markingSpot) {
    if (ev.type === 'click') await markSpot(ev);
    return;
  }
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
  // Line widths in the picture's pixels, at least 1.5 CSS px however small the picture is shown
  // (a 1280 × 960 camera picture in a landscape viewfinder is drawn at ~0.18 CSS px per pixel).
  const rect = canvas.getBoundingClientRect();
  const scale = Math.min(rect.width / w, rect.height / h);
  const lw = Math.max(3, w / 200, scale > 0 ? 1.5 / scale : 0);
  g.lineWidth = lw;
  g.strokeStyle = '#ffd400';
  g.beginPath(); g.arc(marks.circle.cx, marks.circle.cy, marks.circle.r, 0, 2 * Math.PI); g.stroke();
  // The horizon: white dashes on a black line, visible on a bright sky and a dark housing alike.
  g.lineWidth = 2 * lw;
  g.strokeStyle = '#000000';
  g.beginPath(); g.arc(marks.horizon.cx, marks.horizon.cy, marks.horizon.r, 0, 2 * Math.PI); g.stroke();
  g.lineWidth = 1.4 * lw;
  g.setLineDash([4 * lw, 3 * lw]);
  g.strokeStyle = '#ffffff';
  g.beginPath(); g.arc(marks.horizon.cx, marks.horizon.cy, marks.horizon.r, 0, 2 * Math.PI); g.stroke();
  g.setLineDash([]);
  g.lineWidth = lw;
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
    // Capture only where the camera confirmed manual exposure.
    $('capture').disabled = !caps;
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
  keepOfferInView();
}

/** An offer on the camera screen (no circle found, a squeezed bracket) stays in view when the
 *  status line above it is rewritten (the camera restarting after a merge does that). */
function keepOfferInView() {
  const box = ['squeezed', 'no-circle'].map((id) => $(id)).find((b) => !b.hidden);
  if (box) box.scrollIntoView({ block: 'nearest' });
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
    const times = shot.frames.map((f) => f.time_s);
    const steps = squeezedSteps(times, settings.spacing);
    document.body.dataset.capture = JSON.stringify({ requested: shot.requested, readBack: shot.readBack, heading, time: when, steps });
    if (steps && !(await acceptSqueezed(times, steps, settings.spacing))) {
      $('camera-status').textContent = 'Not merged: tap Capture to take the bracket again.';
      return;
    }
    const frames = [];
    for (const f of shot.frames) frames.push({ name: f.name, bytes: await f.blob.arrayBuffer() });
    lastRunSource = 'camera';
    await merge(frames, times, { time: when }, { honoured: true });
  } catch (err) {
    await showError(err);
  } finally {
    $('capture').disabled = !camera.manualExposure();
  }
}

/** The steps between the exposures taken, in EV, when one is more than 0.25 EV off the spacing
 *  asked for (the camera's range of exposure times could not hold the bracket); else null. */
function squeezedSteps(times, spacing) {
  const steps = times.slice(1).map((t, i) => Math.log2(t / times[i]));
  return steps.some((s) => Math.abs(s - spacing) > 0.25) ? steps : null;
}

/** Says what a squeezed bracket is and asks whether to merge it; resolves to true to merge,
 *  false to take it again (or when the question is dismissed by other work, clearMessage). */
function acceptSqueezed(times, steps, spacing) {
  const box = $('squeezed');
  const evs = steps.map((s) => s.toFixed(1));
  const apart = evs.length > 1 ? `${evs.slice(0, -1).join(', ')} and ${evs[evs.length - 1]}` : evs[0];
  $('squeezed-text').textContent = `The camera's exposure times could not hold ${times.length} photos ${spacing} EV apart: it took ${times.map(timeText).join(', ')} s, ${apart} EV apart. Merge these, or take the bracket again (fewer photos or a smaller spacing in Settings fit the camera).`;
  $('camera-status').textContent = 'Bracket taken with smaller steps than asked.';
  box.hidden = false;
  box.scrollIntoView({ block: 'nearest' });
  return new Promise((resolve) => {
    squeezedAnswer = (merge) => {
      squeezedAnswer = null;
      box.hidden = true;
      resolve(merge);
    };
    $('squeezed-merge').onclick = () => squeezedAnswer && squeezedAnswer(true);
    $('squeezed-retake').onclick = () => squeezedAnswer && squeezedAnswer(false);
  });
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
    } else {
      // Photos without an exposure time in EXIF: a field per photo (pre-filled where EXIF has
      // one) instead of an error. EXIF sits in a JPEG's first blocks; other files go whole.
      const metas = [];
      for (const f of files) {
        const bytes = await (/\.jpe?g$/i.test(f.name) ? f.slice(0, 256 * 1024) : f).arrayBuffer();
        metas.push(await ask('metadata', { bytes }, null, [bytes]));
      }
      if (metas.some((m) => m.exposure_time_s == null)) {
        askTimes(files, metas);
        return;
      }
    }
    await mergeFiles(files, times);
  } catch (err) { await showError(err); }
}

async function mergeFiles(files, times) {
  const frames = [];
  for (const f of files) frames.push({ name: f.name, bytes: await f.arrayBuffer() });
  lastRunSource = 'gallery';
  await merge(frames, times);
}

/** A time for the field: 1/250 below a second, else seconds. */
function timeText(t) {
  if (t == null) return '';
  return t < 1 ? `1/${Math.round(1 / t)}` : String(t);
}

let timesFiles = null;

/** The exposure-time form: one field per picked photo, in the order picked. */
function askTimes(files, metas) {
  timesFiles = files;
  const ol = $('times-list');
  ol.replaceChildren();
  files.forEach((f, i) => {
    const li = document.createElement('li');
    const label = document.createElement('label');
    label.append(`${f.name}, seconds `);
    const input = document.createElement('input');
    input.type = 'text';
    input.inputMode = 'decimal';
    input.name = `time-${i}`;
    input.placeholder = '1/250';
    input.value = timeText(metas[i].exposure_time_s);
    input.required = true;
    label.append(input);
    li.append(label);
    ol.append(li);
  });
  $('times-form').hidden = false;
  const first = [...ol.querySelectorAll('input')].find((x) => !x.value);
  if (first) first.focus();
  $('times-form').scrollIntoView({ block: 'nearest' });
}

async function submitTimes(ev) {
  ev.preventDefault();
  clearMessage();
  const files = timesFiles;
  if (!files) return;
  try {
    // Each field is read by the core as the command line reads a --times-file line, so
    // "1/250", "0.004" and "2" mean what they mean there; its message names the photo.
    const times = [];
    for (const [i, f] of files.entries()) {
      const v = $('times-list').querySelector(`[name="time-${i}"]`).value.trim();
      if (!v) throw new Sentence(`Type the exposure time of ${f.name} (as 1/250 or 0.004 seconds).`);
      const [t] = await ask('times', { listName: f.name, text: `photo ${v}\n`, names: ['photo'] });
      times.push(t);
    }
    $('times-form').hidden = true;
    timesFiles = null;
    await mergeFiles(files, times);
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
  // Leaving Settings: a notice about it (a profile imported) has been read; on the camera screen
  // it would push the viewfinder below the fold in landscape.
  const closeSettings = () => {
    saveSettings();
    if ($('message').className === 'info') $('message').hidden = true;
    show('camera');
  };
  $('settings-done').onclick = closeSettings;
  $('gallery').addEventListener('change', fromGallery);
  $('times-form').addEventListener('submit', submitTimes);
  $('times-cancel').onclick = () => { $('times-form').hidden = true; timesFiles = null; };
  $('view-toggle').onclick = () => showView($('view-toggle').getAttribute('aria-pressed') !== 'true');
  $('meter-mark').onclick = () => {
    markingSpot = !markingSpot;
    $('meter-mark').setAttribute('aria-pressed', String(markingSpot));
    if (markingSpot) showView(false);
    $('meter-spot-at').textContent = markingSpot ? 'Now tap the place the meter pointed at.' : $('meter-spot-at').textContent;
  };
  $('meter-apply').onclick = applyReadings;
  $('settings-done-top').onclick = closeSettings;
  $('capture').onclick = capture;
  $('cancel').onclick = () => { cancelWork(); show('camera'); showInfo('Cancelled: nothing was saved.'); };
  $('back').onclick = () => {
    clearMessage();
    spot = null;
    $('meter-lux').value = '';
    $('meter-cd').value = '';
    show('camera');
  };
  for (const id of Object.keys(saves)) $(id).onclick = () => save(id);
  $('share').hidden = !(navigator.canShare && navigator.canShare({ files: [new File([''], 'x.hdr')] }));
  $('share').onclick = share;
  $('import').addEventListener('change', importProfile);
  const img = $('preview');
  img.addEventListener('dblclick', onPreviewTap);
  img.addEventListener('touchend', onPreviewTap);
  img.addEventListener('click', onPreviewTap);
  compass.start((h) => {
    $('heading').textContent = `${h.toFixed(1)}° (top edge)`;
    $('compass-permission').hidden = true;
    updateMarks();
  }, () => {
    const b = $('compass-permission');
    b.hidden = false;
    b.onclick = () => {
      $('heading').textContent = 'asking for the compass…';
      compass.requestPermission()
        .then(() => { b.hidden = true; $('heading').textContent = 'waiting for the first reading (turn the phone a little)'; })
        .catch((err) => { $('heading').textContent = 'not allowed'; showError(err); });
    };
  });
}

startWorker();
// Which core the worker loaded ({build, threads, reason}), for the browser tests.
ask('core').then((c) => { document.body.dataset.core = c.build; document.body.dataset.threads = String(c.threads); }).catch(() => {});
window.__skydomeAsk = ask; // for web-tests/measure.mjs (the worker's memory)
wire();
show('camera');
startCamera();
if ('serviceWorker' in navigator) {
  navigator.serviceWorker.register('sw.js').catch(() => {});
  // The isolation shim (sw.js adds COOP/COEP to every response, for hosts that cannot): a page
  // loaded before the service worker controlled it is not isolated, so it reloads once, when
  // nothing is under way, to get the threaded core. Once per tab: a browser that will not
  // isolate keeps the single-threaded core without reloading again.
  if (!window.crossOriginIsolated && window.isSecureContext) {
    const reload = () => {
      if (!navigator.serviceWorker.controller || sessionStorage.getItem('skydome.isolationReload')) return;
      if (document.body.dataset.screen !== 'camera') { setTimeout(reload, 2000); return; }
      sessionStorage.setItem('skydome.isolationReload', '1');
      location.reload();
    };
    navigator.serviceWorker.addEventListener('controllerchange', reload);
    reload();
  }
}
