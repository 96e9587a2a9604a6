// Camera and lens profiles stored in the browser (IndexedDB), as the same JSON files the
// command line reads and writes (`skydome calibrate -o camera.json`, `skydome lens fit -o
// lens.json`). A record is {id, kind: 'camera'|'lens', name, json, active, saved}.

const DB = 'skydome';
const STORE = 'profiles';

function open() {
  return new Promise((resolve, reject) => {
    const req = indexedDB.open(DB, 1);
    req.onupgradeneeded = () => {
      req.result.createObjectStore(STORE, { keyPath: 'id', autoIncrement: true });
    };
    req.onsuccess = () => resolve(req.result);
    req.onerror = () => reject(req.error);
  });
}

async function tx(mode, fn) {
  const db = await open();
  return new Promise((resolve, reject) => {
    const t = db.transaction(STORE, mode);
    const out = fn(t.objectStore(STORE));
    t.oncomplete = () => { db.close(); resolve(out && 'result' in out ? out.result : out); };
    t.onerror = () => { db.close(); reject(t.error); };
  });
}

/** All stored profiles, newest first. */
export async function list() {
  const all = await tx('readonly', (s) => s.getAll());
  return all.sort((a, b) => b.saved - a.saved);
}

/** The active profile of a kind ('camera' or 'lens'), or null. */
export async function active(kind) {
  return (await list()).find((p) => p.kind === kind && p.active) || null;
}

/** Stores a profile; `makeActive` makes it the one used for merging (others of its kind are
 *  deactivated). Returns its id. */
export async function save(kind, name, json, makeActive) {
  const all = await list();
  return tx('readwrite', (s) => {
    if (makeActive) {
      for (const p of all) if (p.kind === kind && p.active) s.put({ ...p, active: false });
    }
    return s.add({ kind, name, json, active: !!makeActive, saved: Date.now() });
  });
}

/** Makes profile `id` the active one of its kind, or (active = false) none. */
export async function setActive(id, on) {
  const all = await list();
  const target = all.find((p) => p.id === id);
  if (!target) return;
  await tx('readwrite', (s) => {
    for (const p of all) {
      if (p.kind !== target.kind) continue;
      const want = on && p.id === id;
      if (p.active !== want) s.put({ ...p, active: want });
    }
  });
}

/** Deletes profile `id`. */
export async function remove(id) {
  await tx('readwrite', (s) => s.delete(id));
}

/** Which kind a profile file is: lens profiles have a circle and a projection, camera
 *  profiles have the response curves `g`. */
export function kindOf(text) {
  let v;
  try { v = JSON.parse(text); } catch { return null; }
  if (v && typeof v === 'object' && 'circle' in v && 'projection' in v) return 'lens';
  if (v && typeof v === 'object' && 'g' in v) return 'camera';
  return null;
}
