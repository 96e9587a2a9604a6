// A decoding worker (started by worker.js): it decodes photos with the core's own decoder
// (skydome's bracket::decode compiled to wasm), so the photos of a bracket decode on several
// cores, and hands each back as its metadata and its samples (transferred, not copied).
//
// Message in: {i, name, bytes}; out: {i, meta, pixels} or {i, error: 'the core's message'}.
// After loading it decodes two small JPEGs many times, so its decoder is compiled to optimised
// code before the first real photo (see skydome_web::warm_up_decoding; it decodes nothing else,
// so the whole pipeline's warm-up, skydome_web::warm_up, would be wasted here).
import init, { decode_photo, warm_up_decoding } from './pkg/skydome_web.js';

const ready = init().then(() => {
  try { warm_up_decoding(24); } catch (err) { console.warn(`decoder warm-up: ${err && err.message ? err.message : err}`); }
});

self.onmessage = async (e) => {
  const { i, name, bytes } = e.data;
  try {
    await ready;
    const photo = decode_photo(name, new Uint8Array(bytes));
    const meta = photo.meta_json();
    const pixels = photo.take_pixels();
    photo.free();
    postMessage({ i, meta, pixels: pixels.buffer }, [pixels.buffer]);
  } catch (err) {
    postMessage({ i, error: String(err && err.message ? err.message : err) });
  }
};
