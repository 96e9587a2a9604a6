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
RUSTFLAGS="-C target-feature=+simd128" cargo build -p skydome-web --target wasm32-unknown-unknown --release
TMP="$OUT.tmp"
rm -rf "$TMP"
mkdir -p "$TMP"
cp -r crates/skydome-web/www/. "$TMP/"
"$WB" --target web --no-typescript --out-dir "$TMP/pkg" target/wasm32-unknown-unknown/release/skydome_web.wasm
# The service worker's cache name changes with every build whose files change.
HASH="$(cd "$TMP" && find . -type f ! -name sw.js -print0 | sort -z | xargs -0 sha256sum | sha256sum | cut -c1-12)"
sed -i "s/@BUILD@/$HASH/" "$TMP/sw.js"
rm -rf "$OUT"
mv "$TMP" "$OUT"
echo "built $OUT ($(gzip -9 -c "$OUT/pkg/skydome_web_bg.wasm" | wc -c) bytes of gzipped wasm)"
