// Service worker: the app works offline after the first visit. Every file of the app is cached
// at install; requests for them are answered from the cache first (the app is versioned by
// CACHE, which build.sh stamps with the build's hash). Nothing else is fetched: photos never
// leave the phone.
const CACHE = 'skydome-@BUILD@';
const FILES = [
  './', 'index.html', 'app.css', 'app.js', 'camera.js', 'compass.js', 'profiles.js', 'worker.js', 'decoder.js',
  'manifest.webmanifest', 'icons/icon.svg', 'icons/icon-192.png', 'icons/icon-512.png',
  'pkg/skydome_web.js', 'pkg/skydome_web_bg.wasm',
];

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

self.addEventListener('fetch', (e) => {
  const url = new URL(e.request.url);
  if (e.request.method !== 'GET' || url.origin !== self.location.origin) return;
  e.respondWith(
    caches.open(CACHE).then((c) => c.match(e.request, { ignoreSearch: true }).then((hit) => hit || fetch(e.request))),
  );
});
