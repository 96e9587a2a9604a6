// The Web Worker that owns the WebAssembly core. Every image operation happens in
// skydome::pipeline (compiled to wasm); this file only moves bytes and forwards progress.
//
// Messages in: {id, type, ...}; messages out: {id, progress: {stage, fraction}} while running,
// then {id, result} or {id, error: 'One human sentence.'}.
import init, {
  Job, detect_circle, photo_exposure, check_camera_profile, check_lens_profile, live_overlay, list_times, version,
  warm_up,
} from './pkg/skydome_web.js';

const ready = init();
// Once loaded, the core merges a tiny synthetic bracket (about 0.1 s) so the browser compiles
// its loops into optimised code before the user's first merge (see skydome_web::warm_up);
// skipped when a merge came first.
let merged = false;
ready.then(() => setTimeout(() => {
  if (merged) return;
  try { warm_up(256); warm_up(256); } catch (err) { console.warn(`warm-up: ${sentence(err)}`); }
}, 0));
let job = null;      // the photos of the current bracket (kept for a second run, e.g. a tapped sun)
let outcome = null;  // the last run's products, encoded on demand

function sentence(err) {
  const msg = String(err && err.message ? err.message : err).split(/\s+/).join(' ').trim();
  if (!msg) return 'Something went wrong.';
  // Capitalised unless it starts with a file name, which keeps its spelling.
  const first = msg.split(/[ :]/)[0].replace(/[,;!?.]+$/, '');
  const s = /^[\p{L}']+$/u.test(first) ? msg[0].toUpperCase() + msg.slice(1) : msg;
  return /[.!?]$/.test(s) ? s : s + '.';
}

function runJob(id, optionsJson, times) {
  merged = true;
  if (outcome) { outcome.free(); outcome = null; }
  const t0 = performance.now();
  // Milliseconds spent in each stage (from its first progress event to the next stage's), for
  // web-tests/measure.mjs.
  const stages = {};
  let current = null;
  let since = t0;
  const mark = (next) => {
    const now = performance.now();
    if (current) stages[current] = (stages[current] || 0) + (now - since);
    current = next;
    since = now;
  };
  outcome = job.run(optionsJson, new Float64Array(times || []), (stage, fraction) => {
    if (stage !== current) mark(stage);
    postMessage({ id, progress: { stage, fraction } });
    return false; // cancelling is done by terminating this worker (see app.js)
  });
  mark(null);
  return {
    report: JSON.parse(outcome.report_json()),
    width: outcome.width(),
    height: outcome.height(),
    camera_profile: outcome.camera_profile_json(),
    lens_profile: outcome.lens_profile_json(),
    ms: performance.now() - t0,
    stages,
  };
}

const products = {
  hdr: () => outcome.hdr(),
  exr: () => outcome.exr(),
  equirect: () => outcome.equirect_hdr(),
  preview: () => outcome.preview_jpeg(),
  overlay: () => outcome.overlay_jpeg(),
};

const handlers = {
  async version() { return version(); },
  async run({ frames, options, times }) {
    if (job) job.free();
    job = new Job();
    for (const f of frames) job.add_frame(f.name, new Uint8Array(f.bytes));
    return runJob(this.id, options, times);
  },
  async rerun({ options, times }) {
    if (!job) throw new Error('there is no bracket to merge again; pick or capture the photos');
    return runJob(this.id, options, times);
  },
  async product({ name }) {
    if (!outcome) throw new Error('nothing has been merged yet');
    const bytes = products[name]();
    return { bytes: bytes.buffer, transfer: [bytes.buffer] };
  },
  async inputPixel({ x, y }) {
    const p = outcome.to_input_pixel(x, y);
    return { x: p[0], y: p[1] };
  },
  async exposure({ name, bytes }) { return JSON.parse(photo_exposure(name, new Uint8Array(bytes))); },
  async circle({ name, bytes }) { return JSON.parse(detect_circle(name, new Uint8Array(bytes))); },
  async times({ listName, text, names }) { return Array.from(list_times(listName, text, names)); },
  async checkCamera({ json }) { return check_camera_profile(json); },
  async checkLens({ json }) { return check_lens_profile(json); },
  async overlay({ lens, circle, model, fov }) {
    return JSON.parse(live_overlay(lens || '', JSON.stringify(circle || {}), model, fov, NaN));
  },
  async memory() {
    // The wasm linear memory never shrinks: its size is the high-water mark of the core.
    return { wasmBytes: wasmMemory() };
  },
};

let memoryRef = null;
function wasmMemory() { return memoryRef ? memoryRef.buffer.byteLength : 0; }

self.onmessage = async (e) => {
  const { id, type } = e.data;
  try {
    const wasm = await ready;
    memoryRef = wasm.memory;
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
    postMessage({ id, error: sentence(err) });
  }
};
