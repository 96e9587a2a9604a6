// The camera: live preview and the bracket, through the W3C Image Capture API.
//
// Units: the API's exposureTime is in units of 100 µs (so 1/100 s = 100); this module converts
// to seconds only when it hands times to the core. Chrome does not check that a camera obeys
// a constraint, so every shot is checked afterwards (track.getSettings() and the photo's EXIF).

/** Thrown when the camera cannot do what the bracket needs; `message` is one sentence. */
export class CameraRefusal extends Error {}

let stream = null;
let track = null;

/** Starts the rear camera and shows it in `video`. */
export async function start(video) {
  if (!navigator.mediaDevices || !navigator.mediaDevices.getUserMedia) {
    throw new CameraRefusal('This browser gives no camera access here; pick photos from the gallery instead.');
  }
  stream = await navigator.mediaDevices.getUserMedia({
    // The live view needs no full resolution (takePhoto() uses the sensor's own photo size);
    // a small stream keeps its frame buffers out of the merge's memory.
    video: { facingMode: { ideal: 'environment' }, width: { ideal: 1280 }, height: { ideal: 960 } },
    audio: false,
  });
  track = stream.getVideoTracks()[0];
  video.srcObject = stream;
  await video.play().catch(() => {});
  return track;
}

/** Stops the camera (while the core merges: frees the preview's frame buffers and battery). */
export function stop() {
  if (stream) for (const t of stream.getTracks()) t.stop();
  stream = null;
  track = null;
}

/** Whether the camera is running. */
export function running() { return !!track && track.readyState === 'live'; }

/** What manual exposure this camera offers: null when the bracket cannot be taken (Safari on
 *  iOS and desktop browsers expose no exposureMode/exposureTime). */
export function manualExposure() {
  if (!track || typeof ImageCapture === 'undefined' || !track.getCapabilities) return null;
  const caps = track.getCapabilities();
  const modes = caps.exposureMode || [];
  if (!modes.includes('manual') || !caps.exposureTime) return null;
  return caps;
}

/** Snaps `v` into a numeric capability {min, max, step}. */
function fit(cap, v) {
  let x = Math.min(cap.max, Math.max(cap.min, v));
  if (cap.step > 0) x = cap.min + Math.round((x - cap.min) / cap.step) * cap.step;
  return Math.min(cap.max, Math.max(cap.min, x));
}

/** Builds one constraint set key by key from getCapabilities(): a key the camera does not list
 *  is left out (one unsupported key would reject the whole request), a value outside a numeric
 *  range is snapped into it, a mode the camera does not offer is left out. Returns the set and
 *  the keys that were dropped. */
export function buildConstraints(caps, wanted) {
  const set = {};
  const dropped = [];
  for (const [key, value] of Object.entries(wanted)) {
    const cap = caps[key];
    if (cap === undefined || value === undefined) { dropped.push(key); continue; }
    if (Array.isArray(cap)) {
      if (cap.includes(value)) set[key] = value; else dropped.push(key);
    } else if (typeof cap === 'object' && 'min' in cap) {
      set[key] = fit(cap, value);
    } else {
      dropped.push(key);
    }
  }
  return { set, dropped };
}

/** The exposure times (100 µs units) of a bracket of `shots` frames `spacing` EV apart around
 *  `t0`, moved as a whole into the camera's range when it does not fit there, then snapped to
 *  its steps. Throws when the range cannot hold distinct times. */
export function bracketTimes(cap, t0, shots, spacing) {
  const half = (shots - 1) / 2;
  let centre = t0;
  const lo = centre * 2 ** (-half * spacing);
  const hi = centre * 2 ** (half * spacing);
  if (lo < cap.min) centre *= cap.min / lo;
  else if (hi > cap.max) centre *= cap.max / hi;
  if (centre * 2 ** (half * spacing) > cap.max) centre = Math.sqrt(cap.min * cap.max);
  const times = [];
  for (let i = 0; i < shots; i++) times.push(fit(cap, centre * 2 ** ((i - half) * spacing)));
  for (let i = 1; i < times.length; i++) {
    if (!(times[i] > times[i - 1])) {
      throw new CameraRefusal(`This camera's exposure times (${cap.min / 10}–${cap.max / 10} ms) cannot hold ${shots} different exposures ${spacing} EV apart; choose fewer shots or a smaller spacing.`);
    }
  }
  return times;
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** Takes the bracket. `exifTime(blob)` returns the photo's EXIF exposure time in seconds (or
 *  null); `onStep(text)` reports progress. Returns {frames: [{name, blob, time_s}], settings}.
 *  Refuses (CameraRefusal) when the camera did not apply a requested exposure. */
export async function captureBracket({ iso, shots, spacing }, exifTime, onStep) {
  const caps = manualExposure();
  if (!caps) {
    throw new CameraRefusal('This camera offers no manual exposure in this browser; pick bracketed photos from the gallery instead.');
  }
  const capture = new ImageCapture(track);
  // 1. Lock ISO, white balance and focus; let auto-exposure settle and read t0.
  const lock = buildConstraints(caps, {
    exposureMode: 'continuous', iso, whiteBalanceMode: 'manual', focusMode: 'manual',
  });
  await track.applyConstraints({ advanced: [lock.set] });
  onStep('Letting the exposure settle…');
  await sleep(800);
  const auto = track.getSettings();
  const t0 = auto.exposureTime || Math.sqrt(caps.exposureTime.min * caps.exposureTime.max);
  const wantedTimes = bracketTimes(caps.exposureTime, t0, shots, spacing);

  const frames = [];
  const readBack = [];
  for (const [i, t] of wantedTimes.entries()) {
    onStep(`Taking photo ${i + 1} of ${wantedTimes.length} (${(t / 10).toFixed(1)} ms)…`);
    const c = buildConstraints(caps, {
      exposureMode: 'manual', exposureTime: t, iso, whiteBalanceMode: 'manual', focusMode: 'manual',
    });
    await track.applyConstraints({ advanced: [c.set] });
    await sleep(300); // a few frames for the sensor to take the new time
    const s = track.getSettings();
    readBack.push(s.exposureTime);
    if (s.exposureMode !== 'manual' || Math.abs((s.exposureTime ?? -1) - c.set.exposureTime) > Math.max(1, 0.05 * c.set.exposureTime)) {
      throw new CameraRefusal(`The camera ignored the requested exposure time (asked ${(c.set.exposureTime / 10).toFixed(1)} ms, it reports ${s.exposureTime == null ? 'none' : (s.exposureTime / 10).toFixed(1) + ' ms'}), so no bracket was taken.`);
    }
    const blob = await capture.takePhoto();
    // Named as the user would call them: the core's messages name the photo.
    const name = `photo ${i + 1} of ${wantedTimes.length}.jpg`;
    const exif = await exifTime(blob, name);
    const asked = c.set.exposureTime * 1e-4;
    if (exif != null && Math.abs(Math.log2(exif / asked)) > 0.35) {
      throw new CameraRefusal(`The camera ignored the requested exposure time (asked ${(asked * 1000).toFixed(1)} ms, the photo says ${(exif * 1000).toFixed(1)} ms), so no bracket was taken.`);
    }
    frames.push({ name, blob, time_s: exif ?? s.exposureTime * 1e-4 });
  }
  // Back to automatic exposure for the live view.
  await track.applyConstraints({ advanced: [buildConstraints(caps, { exposureMode: 'continuous' }).set] }).catch(() => {});
  return { frames, requested: wantedTimes, readBack, iso: lock.set.iso ?? null, dropped: lock.dropped };
}

/** One still of the live view as JPEG bytes (for finding the lens circle). */
export async function grabFrame(video) {
  const w = video.videoWidth;
  const h = video.videoHeight;
  if (!w || !h) return null;
  const c = new OffscreenCanvas(w, h);
  c.getContext('2d').drawImage(video, 0, 0);
  const blob = await c.convertToBlob({ type: 'image/jpeg', quality: 0.9 });
  return { bytes: await blob.arrayBuffer(), width: w, height: h };
}
