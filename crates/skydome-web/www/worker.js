// The Web Worker that owns the WebAssembly core. Every image operation happens in
// skydome::pipeline (compiled to wasm); this file only moves bytes and forwards progress.
//
// Messages in: {id, type, ...}; messages out: {id, progress: {stage, fraction, overall}} while
// running (skydome_web::StageProgress: the stage names and their order are the core's), then
// {id, result} or {id, error: 'One human sentence.'} (the core's skydome_web::sentence).
//
// Two builds of the same core: pkg-mt/ (threaded: the library's rayon parallelism on a pool of
// Web Workers, wasm-bindgen-rayon) is loaded when the page is cross-origin isolated (COOP/COEP
// headers, or the service worker's shim; see docs/phone.md), else pkg/ (single-threaded). They
// write the same bytes. `?threads=N` on this worker's URL (from the page's own `?threads=N`)
// sets the pool's size; 0 forces the single-threaded build.

let Job, detect_circle, photo_exposure, photo_metadata, check_camera_profile, check_lens_profile, live_overlay,
  list_times, decoding_progress, sentence, warm_up, warm_up_decoding, reserve_heap, warm_up_stages,
  warm_up_stages_rounds;
/** Which core runs: {build: 'threaded' | 'single', threads, reason} (reason: why single). */
let coreInfo = null;

const asked = new URL(self.location.href).searchParams.get('threads');
const poolSize = asked != null && asked !== '' && Number.isFinite(Number(asked))
  ? Math.max(0, Math.floor(Number(asked)))
  : Math.min(8, Math.max(1, navigator.hardwareConcurrency || 1));

async function loadCore() {
  let reason = null;
  if (poolSize === 0) reason = 'asked for one thread';
  else if (self.crossOriginIsolated !== true || typeof SharedArrayBuffer !== 'function') {
    reason = 'the page is not cross-origin isolated';
  } else {
    try {
      const m = await import('./pkg-mt/skydome_web.js');
      const wasm = await m.default();
      await m.initThreadPool(poolSize);
      return { m, wasm, info: { build: 'threaded', threads: m.core_threads(), reason: null } };
    } catch (err) {
      reason = `the threaded core did not start (${messageOf(err)})`;
      console.warn(`skydome: ${reason}; using the single-threaded core`);
    }
  }
  const m = await import('./pkg/skydome_web.js');
  const wasm = await m.default();
  return { m, wasm, info: { build: 'single', threads: 1, reason } };
}

// The most a bracket's photos may take decoded at once (skydome Options.frame_memory_budget): a
// phone's tab is killed near 1 GB, and a 9 × 12 MP bracket is 324 MB decoded, so a bracket above
// 256 MiB is read one photo at a time (the same bytes, at about 1.6× the core's time; a 3 × 12 MP
// bracket, 108 MB, is decoded whole, the fast way). `?memory=MiB` on this worker's URL (from the
// page's own) sets it; `?memory=none`, no limit.
/** This worker's `?name=N` as a whole number ≥ 0 (MiB or a count), or `dflt` when absent or not a number. */
function countParam(name, dflt) {
  const v = new URL(self.location.href).searchParams.get(name);
  return v != null && v !== '' && Number.isFinite(Number(v)) ? Math.max(0, Math.floor(Number(v))) : dflt;
}
const frameBudget = new URL(self.location.href).searchParams.get('memory') === 'none' ? null
  : countParam('memory', 256) * 2 ** 20;

/** `optionsJson` with the frame memory budget set (unless the page set one). */
function withBudget(optionsJson) {
  const o = JSON.parse(optionsJson);
  if (!('frame_memory_budget' in o)) o.frame_memory_budget = frameBudget;
  return JSON.stringify(o);
}

let memoryRef = null;
const ready = loadCore().then(({ m, wasm, info }) => {
  ({
    Job, detect_circle, photo_exposure, photo_metadata, check_camera_profile, check_lens_profile, live_overlay,
    list_times, decoding_progress, sentence, warm_up, warm_up_decoding, reserve_heap, warm_up_stages,
    warm_up_stages_rounds,
  } = m);
  coreInfo = info;
  memoryRef = wasm.memory || null;
  return wasm;
});
// Once loaded, while the app waits for the user, the core warms up in steps (each its own task,
// so a merge asked for meanwhile starts after the current step and skips the rest), the
// cheapest and surest first:
// - it decodes two small JPEGs many times (4:4:4 and 4:2:0; skydome_web::warm_up_decoding,
//   about 0.05 s), so the browser has optimised the decoder before the first photo: it
//   optimises a function only after it has run a while, and a running call keeps its slow code
//   (after one 256² merge alone, the first two 12 MP photos decoded in slow code on the test
//   machine; web-tests/profile.mjs --trace shows what is compiled during a merge);
// - it grows its memory to what a phone's 3 × 12 MP bracket needs and frees it again, so the
//   first merge does not wait for the memory to grow (skydome_web::reserve_heap: about 0.3 s of
//   a 1.3–1.5 s first merge on the test machine). `?reserve=MiB` on this worker's URL (from the
//   page's own) sets the reservation; 0, none. 160 MiB: the core's memory after loading (about
//   12 MiB) plus this stays below the 185 MiB a 3 × 12 MP merge reaches, so such a merge's tab
//   peak is not raised (the tab holds it from then on, as after any such merge);
// - it merges a tiny synthetic bracket `?warmup=N` times (default 1; about 0.1 s each;
//   skydome_web::warm_up), so that the pipeline's own loops are optimised too. More merges
//   hardly help: after the decoding warm-up, 22 functions were still optimised during the first
//   12 MP merge with one 256² merge, 21 with three (the sun search, called once per merge, and
//   small helpers). So warm_up also runs the sun search 8 times on a 512² dome
//   (skydome_web::warm_up_sun);
// - it runs, in `?stages=N` steps (default skydome_web::warm_up_stages_rounds(), 4; 0.15–0.25 s
//   each on the test machine), the stages a merge calls once over a whole picture, on 384²
//   synthetic pictures (`?stageside=N` on this worker's URL; skydome_web::warm_up_stages: the
//   lens circle's detection, the preview's tone map, the sky's statistics, the bracket checks,
//   the noise fit and the merge, then the whole pipeline on a 384² bracket): after one 256²
//   merge, or four, V8 still optimised 24 of their functions during the first 12 MP merge
//   (web-tests/profile.mjs --trace), after these steps without the whole pipeline 21 (the
//   merge's own passes over whole pictures: the ceiling scan, the best-exposed count, the
//   crop, the sky's statistics). Each step reports the stages it ran (`warmUp` below, for the
//   tests).
const reserveMiB = countParam('reserve', 160);
const warmUps = countParam('warmup', 1);
/** The stages each `warm_up_stages` step ran, in order (for web-tests). */
const warmUpStages = [];
let merged = false;
/** Milliseconds each idle step took, in order (for web-tests/measure.mjs). */
const idleMs = [];
/** Runs `steps` one task each, in turn, until a merge has started. */
function idleSteps(steps) {
  if (merged || steps.length === 0) return;
  const [step, ...rest] = steps;
  const t0 = performance.now();
  try { step(); } catch (err) { console.warn(`warm-up: ${messageOf(err)}`); }
  idleMs.push(Math.round(performance.now() - t0));
  setTimeout(() => idleSteps(rest), 0);
}
ready.then(() => setTimeout(() => {
  startHelpers();
  idleSteps([
    () => warm_up_decoding(24),
    () => {
      if (reserveMiB > 0 && reserve_heap(reserveMiB) === 0) console.warn(`could not reserve ${reserveMiB} MiB for the first merge`);
    },
    ...Array.from({ length: warmUps }, () => () => warm_up(256)),
    ...Array.from({ length: countParam('stages', warm_up_stages_rounds()) }, () => () => {
      warmUpStages.push(warm_up_stages(countParam('stageside', 0)));
    }),
  ]);
}, 0)).catch(() => {}); // a core that fails to load is reported by the first request
let photos = null;   // the photos of the current bracket as files (kept for a second run, e.g. a tapped sun)
let job = null;      // the bracket handed to the core
let outcome = null;  // the last run's products, encoded on demand

// Decoding workers (decoder.js), one per core beyond this one's, at most three: each decodes
// its share of a bracket's photos while this worker decodes the rest. They start (and warm up)
// while the app is idle and are replaced by fresh ones after each merge, so the memory a
// decoder's WebAssembly grew to while decoding goes back at once. Without nested workers (old
// browsers) this worker decodes every photo itself; the bytes written are the same either way.
const HELPERS = typeof Worker === 'undefined' ? 0 : Math.min(3, Math.max(0, (navigator.hardwareConcurrency || 1) - 1));
let helpers = [];
function startHelpers() {
  helpers = [];
  if (coreInfo && coreInfo.build === 'threaded') return;
  for (let k = 0; k < HELPERS; k++) {
    let h;
    try {
      h = new Worker(new URL('./decoder.js', import.meta.url), { type: 'module' });
    } catch (err) {
      break;
    }
    // A helper that fails outside a merge leaves the pool; its error is handled here, so it
    // does not reach the page as this worker's (which would restart this worker).
    h.onerror = (e) => {
      e.preventDefault();
      console.warn(`a decoding worker stopped: ${e.message || 'unknown error'}`);
      helpers = helpers.filter((x) => x !== h);
      h.terminate();
    };
    helpers.push(h);
  }
}
// Called once the photos are decoded: each decoding worker's WebAssembly memory grew to hold a
// decoded photo and never shrinks, so they end before the merge allocates its radiance (with
// one decoding worker the tab's peak fell from 521–526 to 480 MB on 3 × 12 MP, from 840 to
// 736 MB on 9 × 12 MP). Fresh ones start a few seconds after the run, while the user looks at
// the result.
function stopHelpers() {
  for (const h of helpers) h.terminate();
  helpers = [];
}
function retireHelpers() {
  stopHelpers();
  setTimeout(startHelpers, 3000);
}

// Decodes `frames` into a new job: photo i goes to helper i mod (helpers + 1) when that is a
// helper, else this worker decodes it while the helpers work. The first photo's error wins, as
// when the core decodes them in turn.
async function decodeInto(id, frames, optionsJson) {
  const j = new Job();
  for (const f of frames) j.add_frame(f.name, new Uint8Array(f.bytes));
  // The threaded core decodes the photos itself, several at once in its own pool (one memory,
  // no decoding workers' memories beside it).
  if (coreInfo && coreInfo.build === 'threaded') return j;
  // A run the core reads one photo at a time (above the memory budget, a plain crop to the
  // dome: skydome::pipeline::streams_input) gets the files: decoded here beforehand, every photo
  // of the bracket would be in memory at once (9 × 36 MB for a phone's 12 MP bracket), which is
  // what reading them in turn avoids.
  if (j.streams(optionsJson)) return j;
  const shares = helpers.length + 1;
  const errors = new Array(frames.length).fill(null);
  let done = 0;
  const report = () => {
    done++;
    postMessage({ id, progress: JSON.parse(decoding_progress((0.9 * done) / frames.length)) });
  };
  // Each helper answers its photos by index; if it dies (or never loads), this worker decodes
  // the photos it still owed.
  const pending = new Map(); // photo index -> resolve
  const waits = [];
  helpers.forEach((h, k) => {
    h.onmessage = (e) => {
      const resolve = pending.get(e.data.i);
      pending.delete(e.data.i);
      if (resolve) resolve(e.data);
    };
    h.onerror = (e) => {
      e.preventDefault();
      console.warn(`a decoding worker stopped: ${e.message || 'unknown error'}`);
      for (const [i, resolve] of pending) {
        if (i % shares === k + 1) {
          pending.delete(i);
          resolve({ i, lost: true });
        }
      }
    };
  });
  frames.forEach((f, i) => {
    const h = helpers[(i % shares) - 1];
    if (!h) return;
    waits.push(new Promise((resolve) => pending.set(i, resolve)));
    const bytes = f.bytes.slice(0); // a copy: the photos stay here for a second run
    h.postMessage({ i, name: f.name, bytes }, [bytes]);
  });
  frames.forEach((f, i) => {
    if (helpers[(i % shares) - 1]) return;
    try { j.decode(i); } catch (err) { errors[i] = err; }
    report();
  });
  for (const r of await Promise.all(waits)) {
    try {
      if (r.error) throw new Error(r.error);
      if (r.lost) j.decode(r.i);
      else j.set_decoded(r.i, r.meta, new Uint8Array(r.pixels));
    } catch (err) { errors[r.i] = err; }
    r.pixels = null; // copied into the core: the page's copy can be collected

    report();
  }
  const failed = errors.find((e) => e);
  if (failed) { j.free(); throw failed; }
  return j;
}

function messageOf(err) { return String(err && err.message ? err.message : err); }

// The sentence the page shows for `err`, made by the core. A core that did not load cannot make
// one: then this fixed sentence says so.
function sentenceOf(err) {
  try {
    return sentence(messageOf(err));
  } catch {
    return 'The app\'s core did not load in this browser; reload the page.';
  }
}

function runJob(id, optionsJson, times) {
  if (outcome) { outcome.free(); outcome = null; }
  const t0 = performance.now();
  // Milliseconds spent in each stage (from its first progress event to the next stage's), for
  // web-tests/measure.mjs.
  const stages = {};
  // The wasm memory's size (its high-water mark so far) at the end of each stage, in bytes.
  const stageMemory = { decoded: wasmMemory() };
  let current = null;
  let since = t0;
  const mark = (next) => {
    const now = performance.now();
    if (current) {
      stages[current] = (stages[current] || 0) + (now - since);
      stageMemory[current] = wasmMemory();
    }
    current = next;
    since = now;
  };
  outcome = job.run(optionsJson, new Float64Array(times || []), (event) => {
    const progress = JSON.parse(event);
    if (progress.stage !== current) mark(progress.stage);
    postMessage({ id, progress });
    return false; // cancelling is done by terminating this worker (see app.js)
  });
  mark(null);
  const report = JSON.parse(outcome.report_json());
  return {
    report,
    warnings: (report.warnings || []).map((w) => sentence(w)),
    width: outcome.width(),
    height: outcome.height(),
    camera_profile: outcome.camera_profile_json(),
    lens_profile: outcome.lens_profile_json(),
    ms: performance.now() - t0,
    stages,
    stageMemory,
    core: coreInfo,
    luminance: JSON.parse(outcome.luminance_json()),
  };
}

async function decodeAndRun(id, options, times) {
  if (job) { job.free(); job = null; }
  merged = true;
  const t0 = performance.now();
  try {
    options = withBudget(options);
    job = await decodeInto(id, photos, options);
    stopHelpers();
    // Whether the core reads the photos one at a time (for the tests and measure.mjs).
    const streamed = job.streams(options);
    const decodeMs = performance.now() - t0;
    const result = runJob(id, options, times);
    result.streamed = streamed;
    result.stages.decoding = (result.stages.decoding || 0) + decodeMs;
    result.ms += decodeMs;
    return result;
  } finally {
    retireHelpers();
  }
}

const products = {
  hdr: () => outcome.hdr(),
  exr: () => outcome.exr(),
  equirect: () => outcome.equirect_hdr(),
  preview: () => outcome.preview_jpeg(),
  falsecolour: () => outcome.false_colour_jpeg(),
};

const handlers = {
  async run({ frames, options, times }) {
    photos = frames;
    return decodeAndRun(this.id, options, times);
  },
  async rerun({ options, times }) {
    if (!photos) throw new Error('there is no bracket to merge again; pick or capture the photos');
    return decodeAndRun(this.id, options, times);
  },
  async product({ name }) {
    if (!outcome) throw new Error('nothing has been merged yet');
    if (!products[name]) throw new Error(`there is no product ${name}`);
    const bytes = products[name]();
    return { bytes: bytes.buffer, transfer: [bytes.buffer] };
  },
  async inputPixel({ x, y }) {
    if (!outcome) throw new Error('nothing has been merged yet');
    const p = outcome.to_input_pixel(x, y);
    return { x: p[0], y: p[1] };
  },
  async exposure({ name, bytes }) { return JSON.parse(photo_exposure(name, new Uint8Array(bytes))); },
  async metadata({ bytes }) { return JSON.parse(photo_metadata(new Uint8Array(bytes))); },
  async circle({ name, bytes }) { return JSON.parse(detect_circle(name, new Uint8Array(bytes))); },
  async times({ listName, text, names }) { return Array.from(list_times(listName, text, names)); },
  async checkCamera({ name, json }) { return check_camera_profile(name, json); },
  async checkLens({ name, json }) { return check_lens_profile(name, json); },
  // The live overlay's circle, horizon and north point (skydome_web::live_marks) for a heading
  // (degrees, null: no compass).
  async overlay({ lens, circle, model, fov, heading }) {
    return JSON.parse(live_overlay(lens || '', JSON.stringify(circle || {}), model, fov, heading ?? NaN));
  },
  async sentence({ text }) { return sentence(text); },
  async core() { return coreInfo; },
  // What the idle warm-up did: milliseconds per step (decoding, the reservation, each 256² merge).
  async warmUp() { return { ms: idleMs, stages: warmUpStages }; },
  async memory() {
    // The wasm linear memory never shrinks: its size is the high-water mark of the core.
    return { wasmBytes: wasmMemory() };
  },
};

function wasmMemory() { return memoryRef ? memoryRef.buffer.byteLength : 0; }

self.onmessage = async (e) => {
  const { id, type } = e.data;
  try {
    await ready;
    const h = handlers[type];
    if (!h) throw new Error(`unknown request ${type}`);
    const result = await h.call({ id }, e.data);
    if (result && result.transfer) {
      const { transfer, ...rest } = result;
      postMessage({ id, result: rest }, transfer);
    } else {
      postMessage({ id, result });
    }
  } catch (err) {
    // The core names the kind of failure (skydome_web::WebError::kind) for the page's way out.
    const kind = err && typeof err.name === 'string' && err.name !== 'Error' ? err.name : null;
    postMessage({ id, error: sentenceOf(err), kind });
  }
};
