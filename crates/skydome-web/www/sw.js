// Service worker: the app works offline after the first visit, and is cross-origin isolated on
// hosts that cannot send headers.
//
// Offline: every file of the app (FILES, listed by build.sh) is cached at install; requests for
// them are answered from the cache first (the app is versioned by CACHE, which build.sh stamps
// with the build's hash). Nothing else is fetched: photos never leave the phone.
//
// Isolation shim: the threaded core needs `crossOriginIsolated` (COOP/COEP headers on every
// response). A host like GitHub Pages cannot send them, so every response this worker hands
// the page carries them; the page reloads itself once when this worker first takes control of
// a page that was not isolated (app.js). Where the host sends them already nothing changes.
const CACHE = 'skydome-@BUILD@';
const FILES = ['./', '@FILES@'];

self.addEventListener('install', (e) => {
  e.waitUntil(caches.open(CACHE).then((c) => c.addAll(FILES)).then(() => self.skipWaiting()));
});

self.addEventListener('activate', (e) => {
  e.waitUntil(
    caches.keys()
      .then((keys) => Promise.all(keys.filter((k) => k !== CACHE).map((k) => caches.delete(k))))
      .then(() => self.clients.claim()),
  );
});

/** `r` with the isolation headers (a copy: cached and fetched responses are immutable). */
function isolated(r) {
  if (!r || r.status === 0 || r.type === 'opaque' || r.type === 'opaqueredirect') return r;
  const headers = new Headers(r.headers);
  headers.set('Cross-Origin-Opener-Policy', 'same-origin');
  headers.set('Cross-Origin-Embedder-Policy', 'require-corp');
  headers.set('Cross-Origin-Resource-Policy', 'same-origin');
  return new Response(r.body, { status: r.status, statusText: r.statusText, headers });
}

self.addEventListener('fetch', (e) => {
  const url = new URL(e.request.url);
  if (e.request.method !== 'GET' || url.origin !== self.location.origin) return;
  e.respondWith(
    caches.open(CACHE)
      .then((c) => c.match(e.request, { ignoreSearch: true }).then((hit) => hit || fetch(e.request)))
      .then(isolated),
  );
});
