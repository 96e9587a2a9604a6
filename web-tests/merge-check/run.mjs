// Checks that the noise-aware merge's SIMD128 kernel (crates/skydome/src/merge/fused.rs) gives
// the scalar path's bits: merge-check built with +simd128 (the kernel runs, as in the app) and
// without (the scalar path) merges the same random frames (1–10 frames, black level 0 and 9,
// rows of 37, 64, 203 and 400 pixels: whole steps of eight pixels and scalar tails) and must
// give the same digests. Build both, then compare (from this folder):
//   RUSTFLAGS="-C target-feature=+simd128" cargo build --release --target wasm32-unknown-unknown \
//     && cp target/wasm32-unknown-unknown/release/merge_check.wasm /tmp/simd.wasm
//   cargo build --release --target wasm32-unknown-unknown \
//     && cp target/wasm32-unknown-unknown/release/merge_check.wasm /tmp/scalar.wasm
//   node run.mjs /tmp/simd.wasm /tmp/scalar.wasm
// Prints the cases that differ and exits 1 if any does. With `--time ROUNDS [P W H]` it also
// times the merge of P random frames of W × H (default 3, 2000 × 1500) in both builds, one call
// of each in turn, ROUNDS times (one thread: the check is built without rayon), and prints the
// medians and the median of the paired ratios A / B. (A kernel sabotaged by one constant of
// its `2^x` made 72 of the 80 cases differ: every one with 1–9 frames.)
import fs from 'node:fs';

async function load(file) {
  const mod = await WebAssembly.compile(fs.readFileSync(file));
  // The library links wasm-bindgen; a plain merge calls none of its imports.
  const imports = {};
  for (const i of WebAssembly.Module.imports(mod)) {
    imports[i.module] ??= {};
    if (i.kind === 'function') imports[i.module][i.name] = () => { throw new Error(`${i.module}.${i.name} called`); };
  }
  return (await WebAssembly.instantiate(mod, imports)).exports;
}

const [a, b] = await Promise.all(process.argv.slice(2, 4).map(load));
let differ = 0;
let cases = 0;
for (let p = 1; p <= 10; p++) {
  for (const black of [0, 9]) {
    for (const [w, h] of [[37, 11], [64, 9], [203, 7], [400, 3]]) {
      const [da, db] = [a.merge_digest(p, black, w, h), b.merge_digest(p, black, w, h)];
      cases++;
      if (da !== db || da === 0n) {
        differ++;
        console.log(`${p} frames, black ${black}, ${w}×${h}: ${da.toString(16)} against ${db.toString(16)}`);
      }
    }
  }
}
console.log(`${cases - differ} of ${cases} merges give the same bits`);
const ti = process.argv.indexOf('--time');
if (ti > 0) {
  const rest = process.argv.slice(ti + 1).map(Number);
  const rounds = rest[0];
  const fixed = rest.length >= 4 ? rest.slice(1, 4) : [3, 2000, 1500];
  for (const m of [a, b]) m.prepare(...fixed);
  const times = [[], []];
  const median = (xs) => [...xs].sort((x, y) => x - y)[xs.length >> 1];
  for (let r = 0; r < rounds; r++) {
    for (const [k, m] of [[0, a], [1, b]]) {
      const t0 = performance.now();
      const d = m.merge_prepared();
      times[k].push(performance.now() - t0);
      if (d === 0n) throw new Error('a merge failed');
    }
  }
  console.log(`${fixed[0]} frames of ${fixed[1]} × ${fixed[2]}, ${rounds} rounds: A ${median(times[0]).toFixed(1)} ms, B ${median(times[1]).toFixed(1)} ms, paired A / B ${median(times[0].map((t, i) => t / times[1][i])).toFixed(3)}`);
}
process.exit(differ ? 1 : 0);
