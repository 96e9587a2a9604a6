// The compass.
//
// Heading h = compass azimuth of the phone's TOP edge, degrees from true north towards east
// (skydome's `--north DEG`). From `deviceorientationabsolute` (Chrome): the W3C rotation is
// R = Rz(alpha)·Rx(beta)·Ry(gamma) from the device frame to the earth frame (x east, y north,
// z up), so the top edge (device +y) points along R·(0,1,0) = (−sin α cos β, cos α cos β, sin β)
// and h = atan2(−sin α cos β, cos α cos β). Lying screen-up (β = 0) that is 360° − α; lying
// screen-down flipped over the long edge (γ = ±180°) it is the same, flipped over the short
// edge (β = ±180°) it is 180° − α. On iOS, `webkitCompassHeading` is h directly (after
// DeviceOrientationEvent.requestPermission() from a tap).
//
// The north point drawn on the live picture for h is the core's (skydome_web::live_marks, asked
// for by app.js): h = 0 puts north at the top and east on the LEFT for a phone lying
// screen-down, camera up (the sky is the mirror of a map).

let heading = null;
const listeners = new Set();

/** Compass heading of the top edge from the W3C Euler angles (degrees), or null when the top
 *  edge points straight up or down. */
export function headingFromEuler(alpha, beta, gamma) {
  if (alpha == null || beta == null) return null;
  const a = (alpha * Math.PI) / 180;
  const b = (beta * Math.PI) / 180;
  const x = -Math.sin(a) * Math.cos(b);
  const y = Math.cos(a) * Math.cos(b);
  if (Math.hypot(x, y) < 1e-6) return null;
  const h = (Math.atan2(x, y) * 180) / Math.PI;
  // Tenths of a degree: more than any phone compass resolves.
  return Math.round(((h % 360) + 360) % 360 * 10) / 10 % 360;
}

function emit() { for (const f of listeners) f(heading); }

/** The orientation listener, for `deviceorientationabsolute` (Chrome) or `deviceorientation`
 *  (absolute on some browsers; on iOS relative but carrying `webkitCompassHeading`). Relative
 *  orientation has no north and is ignored. */
function onOrientation(e) {
  let h = null;
  if (typeof e.webkitCompassHeading === 'number') h = Math.round(e.webkitCompassHeading * 10) / 10 % 360;
  else if (e.absolute || e.type === 'deviceorientationabsolute') h = headingFromEuler(e.alpha, e.beta, e.gamma);
  if (h != null) { heading = h; emit(); }
}

/** Starts listening; `onChange(heading)` is called on each reading. `needsTap()` is called
 *  when no reading came within a second and the browser wants a permission tap (iOS). */
export function start(onChange, needsTap) {
  listeners.add(onChange);
  // One listener: the absolute event where the browser has it, else the plain one (which iOS
  // starts sending once the permission is granted).
  const type = 'ondeviceorientationabsolute' in window ? 'deviceorientationabsolute' : 'deviceorientation';
  window.addEventListener(type, onOrientation);
  setTimeout(() => {
    if (heading == null && typeof DeviceOrientationEvent !== 'undefined'
        && typeof DeviceOrientationEvent.requestPermission === 'function') needsTap();
  }, 1000);
}

/** iOS: ask for the compass from a tap. */
export async function requestPermission() {
  const r = await DeviceOrientationEvent.requestPermission();
  if (r !== 'granted') throw new Error('the compass was not allowed; give the north heading in Settings');
}

export function current() { return heading; }
