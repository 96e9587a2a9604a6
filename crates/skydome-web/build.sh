#!/usr/bin/env bash
# Builds the phone app into one folder of static files (default target/skydome-web/app):
#   crates/skydome-web/build.sh [OUT]
# Host that folder over HTTPS for a phone, or run `skydome serve` for this machine.
# Needs the wasm32-unknown-unknown target and wasm-bindgen-cli 0.2.130 (the version pinned in
# Cargo.toml): target/wasm-bindgen-cli/bin/wasm-bindgen, or $WASM_BINDGEN, or on the PATH.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
OUT="${1:-$ROOT/target/skydome-web/app}"
cd "$ROOT"
WB="${WASM_BINDGEN:-}"
if [ -z "$WB" ]; then
  if [ -x target/wasm-bindgen-cli/bin/wasm-bindgen ]; then WB=target/wasm-bindgen-cli/bin/wasm-bindgen
  else WB="$(command -v wasm-bindgen || true)"; fi
fi
if [ -z "$WB" ] || ! "$WB" --version | grep -q ' 0.2.130'; then
  echo "error: wasm-bindgen-cli 0.2.130 not found; install it with" >&2
  echo "  cargo install wasm-bindgen-cli --version 0.2.130 --root target/wasm-bindgen-cli" >&2
  exit 1
fi
# The single-threaded core (pkg/): stable Rust, runs everywhere.
RUSTFLAGS="-C target-feature=+simd128" cargo build -p skydome-web --target wasm32-unknown-unknown --release
TMP="$OUT.tmp"
rm -rf "$TMP"
mkdir -p "$TMP"
cp -r crates/skydome-web/www/. "$TMP/"
"$WB" --target web --no-typescript --out-dir "$TMP/pkg" target/wasm32-unknown-unknown/release/skydome_web.wasm

# The threaded core (pkg-mt/), which the app loads when the page is cross-origin isolated
# (docs/phone.md): the same crate with `--features threads` (rayon on Web Workers through
# wasm-bindgen-rayon), std rebuilt with atomics by the nightly pinned in threads/rust-toolchain.toml
# (installed here when missing), in a target directory of its own so the two builds do not
# rebuild each other. A shared memory needs the linker flags rustc no longer adds for +atomics,
# a declared maximum (4 GiB, wasm32's ceiling, as the single-threaded build's) and the TLS
# exports wasm-bindgen looks for. SKYDOME_WEB_THREADS=0 skips it (the app then always runs
# single-threaded).
# $SKYDOME_NIGHTLY_RUSTUP_HOME puts the nightly in a rustup home of its own (CI: under target/,
# so its cache of target/ keeps the toolchain with the builds); else rustup's usual home.
if [ "${SKYDOME_WEB_THREADS:-1}" != 0 ]; then
  NIGHTLY="$(sed -n 's/^channel = "\(.*\)"$/\1/p' crates/skydome-web/threads/rust-toolchain.toml)"
  NIGHTLY_HOME="${SKYDOME_NIGHTLY_RUSTUP_HOME:-${RUSTUP_HOME:-$HOME/.rustup}}"
  if ! RUSTUP_HOME="$NIGHTLY_HOME" rustup component list --toolchain "$NIGHTLY" --installed 2>/dev/null | grep -q '^rust-src'; then
    RUSTUP_HOME="$NIGHTLY_HOME" rustup toolchain install "$NIGHTLY" --profile minimal --component rust-src --no-self-update
  fi
  RUSTUP_HOME="$NIGHTLY_HOME" \
  CARGO_TARGET_DIR="$ROOT/target/wasm-threads" \
  RUSTFLAGS="-C target-feature=+atomics,+bulk-memory,+mutable-globals,+simd128 \
    -C link-arg=--shared-memory -C link-arg=--import-memory -C link-arg=--max-memory=4294967296 \
    -C link-arg=--export=__wasm_init_tls -C link-arg=--export=__tls_size \
    -C link-arg=--export=__tls_align -C link-arg=--export=__tls_base" \
    cargo +"$NIGHTLY" build -p skydome-web --features threads --target wasm32-unknown-unknown \
      --release -Z build-std=panic_abort,std
  "$WB" --target web --no-typescript --out-dir "$TMP/pkg-mt" \
    target/wasm-threads/wasm32-unknown-unknown/release/skydome_web.wasm
fi

# The service worker caches every file of the app (its list is made here); its cache name
# changes with every build whose files change.
FILES="$(cd "$TMP" && find . -type f ! -name sw.js | sed 's|^\./||' | sort | sed 's/.*/"&"/' | paste -sd, -)"
sed -i "s|'@FILES@'|$FILES|" "$TMP/sw.js"
HASH="$(cd "$TMP" && find . -type f ! -name sw.js -print0 | sort -z | xargs -0 sha256sum | sha256sum | cut -c1-12)"
sed -i "s/@BUILD@/$HASH/" "$TMP/sw.js"
rm -rf "$OUT"
mv "$TMP" "$OUT"
echo "built $OUT ($(gzip -9 -c "$OUT/pkg/skydome_web_bg.wasm" | wc -c) bytes of gzipped wasm$(
  [ -f "$OUT/pkg-mt/skydome_web_bg.wasm" ] && echo ", threaded $(gzip -9 -c "$OUT/pkg-mt/skydome_web_bg.wasm" | wc -c)"))"
