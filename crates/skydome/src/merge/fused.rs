//! The noise-aware merge of 8-bit frames in one vector sweep: the hat's estimate and its
//! refinement ([`Refine`]) for eight samples at a time with AVX2, chosen at run time
//! (`is_x86_feature_detected!`), or four at a time with WebAssembly's SIMD128 when the module
//! is built with it (the app's builds are; wasm has no run-time detection, so it is chosen at
//! compile time). It gives the same bits as the
//! scalar path ([`merge_band`](super::hat)'s hat pass, then [`refine_row`](super::refine)):
//! the same `f32` operations in the same order on every sample, no fused multiply-add.
//!
//! Why it pays: the scalar path looks every code up twice (the hat's table, then the vote
//! table), writes the hat's estimate, its weight-row index and two sums per sample to memory
//! and reads them back. Here each frame's `[vote, factor]` entry is read once and serves both
//! passes; the hat's weight comes from the code by arithmetic (a min and compares). The look-ups
//! are plain loads, not gathers: per eight samples and frame, eight 8-byte loads of the entries,
//! two to a 16-byte half, split into a vector of votes and one of factors by two shuffles; the
//! weight rows four frames at a time by one 16-byte load a sample and a transpose. On AMD Zen an
//! 8-lane gather costs more than its eight loads: at 9 frames the kernel with gathers took 2.5×
//! the hat merge's CPU time, with loads 1.7× (6 MP; see docs/performance.md).
//!
//! The arithmetic stands in for table entries, so [`Fused::new`] checks it against the scalar
//! path's tables for every frame, channel and code and declines (the scalar path runs) on any
//! difference — a weighting this kernel does not know can never change a result.

// Beyond x86-64 and wasm32 with SIMD128 `Fused::new` always declines, and the tables it would
// fill are never read.
#![cfg_attr(
    not(any(
        target_arch = "x86_64",
        all(target_arch = "wasm32", target_feature = "simd128")
    )),
    allow(dead_code)
)]

use super::refine::Refine;

/// Frames the kernel is unrolled for; more take the scalar path.
pub(super) const MAX_FRAMES: usize = 9;
/// Samples per step: eight pixels, so every lane's channel repeats from step to step.
pub(super) const STEP: usize = 24;

/// The vector kernel's tables for one merge of `frames` 8-bit frames (see the module docs).
pub(super) struct Fused {
    frames: usize,
    /// [`Refine`]'s `[vote, factor]` entries: frame-major, then channel, then code.
    votes: Vec<[f32; 2]>,
    /// [`Refine`]'s weight rows, `frames` values a row.
    rows: Vec<f32>,
    /// Per channel: [`Refine`]'s bin offset, last bin and first row.
    off: [f32; 3],
    last: [f32; 3],
    start: [i32; 3],
}

impl Fused {
    /// The kernel's tables for the refinement `r` of 8-bit frames whose hat pass uses `hat`
    /// (per frame, channel and code `[w, w · log2 E_j]`), or `None` when the CPU has no AVX2
    /// (or the wasm module no SIMD128),
    /// the input is not 8-bit, the frame count is beyond [`MAX_FRAMES`], or the kernel's
    /// arithmetic would give any weight other than the tables' (see the module docs).
    pub(super) fn new<const N: usize>(
        r: &Refine<N>,
        hat: impl Fn(usize, usize, usize) -> [f32; 2],
    ) -> Option<Self> {
        if N != 256 || !(1..=MAX_FRAMES).contains(&r.frames) || !available() {
            return None;
        }
        let p = r.frames;
        let entry = |j: usize, c: usize, z: usize| r.votes[(j * 3 + c) * N + z];
        let fused = Self {
            frames: p,
            votes: r.votes.clone(),
            // Padded for the kernel's 16-byte loads of a row (see `avx2::run`).
            rows: r.rows.iter().copied().chain([0.0; 3]).collect(),
            off: r.off,
            last: r.last,
            start: r.start,
        };
        // Every weight the kernel computes must be the table's, bit for bit.
        for j in 0..p {
            for c in 0..3 {
                for z in 0..N {
                    let [vote, _] = entry(j, c, z);
                    let w = hat_weight(j, p, z as u8);
                    let want = hat(j, c, z);
                    if w.to_bits() != want[0].to_bits() || (w * vote).to_bits() != want[1].to_bits()
                    {
                        return None;
                    }
                }
            }
        }
        // Every row a clamped bin can name is in the table (the kernel clamps to it as well).
        for c in 0..3 {
            let end = (fused.start[c] as usize + fused.last[c] as usize + 1) * p;
            if !(0.0..4_194_304.0).contains(&fused.last[c]) || end > fused.rows.len() {
                return None;
            }
        }
        (fused.votes.len() == p * 3 * 256).then_some(fused)
    }

    /// Merges the first whole [`STEP`]s of one row: `rows` holds the row of every frame (8-bit
    /// codes), `out` receives the radiance. Returns how many samples it merged (a multiple of
    /// [`STEP`]); the caller merges the rest.
    pub(super) fn row(&self, rows: &[&[u8]], out: &mut [f32]) -> usize {
        if rows.len() != self.frames {
            return 0;
        }
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: `Fused` exists only where `available()` found AVX2 on this CPU.
            unsafe { avx2::row(self, rows, out) }
        }
        #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
        {
            simd128::row(self, rows, out)
        }
        #[cfg(not(any(
            target_arch = "x86_64",
            all(target_arch = "wasm32", target_feature = "simd128")
        )))]
        {
            let _ = out;
            0
        }
    }
}

/// The hat weight of code `z` in frame `j` of `p` as the kernel computes it: the same as
/// [`weight`](super::hat::weight) for 8-bit codes under the hat (checked by [`Fused::new`]).
fn hat_weight(j: usize, p: usize, z: u8) -> f32 {
    let mut w = z.min(255 - z) as f32;
    if j == 0 && z >= 128 {
        w = super::hat::W_MAX;
    }
    if j + 1 == p && z <= 127 {
        w = super::hat::W_MAX;
    }
    if j == 0 {
        w = w.max(super::hat::W_FLOOR);
    }
    w
}

/// Whether this CPU runs the kernel.
fn available() -> bool {
    #[cfg(test)]
    if tests::SCALAR.with(|s| s.get()) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
    {
        true
    }
    #[cfg(not(any(
        target_arch = "x86_64",
        all(target_arch = "wasm32", target_feature = "simd128")
    )))]
    {
        false
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{Fused, MAX_FRAMES, STEP};
    use crate::fastmath::{EXP2_C, EXP2_LIMIT, EXP2_MAGIC};
    use std::arch::x86_64::*;

    /// [`Fused::row`] for AVX2.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn row(k: &Fused, rows: &[&[u8]], out: &mut [f32]) -> usize {
        match rows.len() {
            1 => run::<1>(k, rows, out),
            2 => run::<2>(k, rows, out),
            3 => run::<3>(k, rows, out),
            4 => run::<4>(k, rows, out),
            5 => run::<5>(k, rows, out),
            6 => run::<6>(k, rows, out),
            7 => run::<7>(k, rows, out),
            8 => run::<8>(k, rows, out),
            9 => run::<9>(k, rows, out),
            _ => 0,
        }
    }

    /// The kernel for `P` frames.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn run<const P: usize>(k: &Fused, rows: &[&[u8]], out: &mut [f32]) -> usize {
        const { assert!(P <= MAX_FRAMES) };
        let n = rows.iter().map(|r| r.len()).fold(out.len(), usize::min) / STEP * STEP;
        let codes: [&[u8]; P] = std::array::from_fn(|j| &rows[j][..n]);
        let out = &mut out[..n];
        let consts = Consts::new::<P>(k);
        let zero = _mm256_setzero_ps();
        let wrows = k.rows.as_ptr();
        // Blocks of up to BLOCK vectors, each in two stages: the hat's estimate and weight row
        // of every vector, then every vector's refinement. A vector's work is one long chain
        // (look-ups, a division, the bin, look-ups that need it, a division, `2^x`); in stages,
        // the independent vectors of a block overlap.
        const BLOCK: usize = 12;
        let mut e0s = [zero; BLOCK];
        let mut bases = [_mm256_setzero_si256(); BLOCK];
        let mut vs = [[zero; P]; BLOCK];
        let mut fs = [[zero; P]; BLOCK];
        let mut s0 = 0;
        while s0 < n {
            let count = ((n - s0) / 8).min(BLOCK);
            // `s0` and `n` are multiples of STEP: vectors come in threes, and the third of a
            // step (its lanes' channels) is a constant in each call of `hat_stage`.
            debug_assert!(s0.is_multiple_of(STEP) && count.is_multiple_of(3));
            let mut v = 0;
            while v < count {
                let s = s0 + 8 * v;
                let c = &consts;
                // SAFETY: `s + 24 ≤ n`, every frame's row length (`count` vectors remain).
                unsafe {
                    (e0s[v], bases[v]) = hat_stage::<P, 0>(k, &codes, s, c, &mut vs[v], &mut fs[v]);
                    (e0s[v + 1], bases[v + 1]) =
                        hat_stage::<P, 1>(k, &codes, s + 8, c, &mut vs[v + 1], &mut fs[v + 1]);
                    (e0s[v + 2], bases[v + 2]) =
                        hat_stage::<P, 2>(k, &codes, s + 16, c, &mut vs[v + 2], &mut fs[v + 2]);
                }
                v += 3;
            }
            for v in 0..count {
                let s = s0 + 8 * v;
                // Every frame's weight for the 8 samples: four frames at a time by one 16-byte
                // load a sample and a transpose.
                let mut wrow = [zero; P];
                let mut b = [0i32; 8];
                // SAFETY: `b` is 8 writable `i32`s.
                unsafe { _mm256_storeu_si256(b.as_mut_ptr().cast(), bases[v]) };
                for (g, cols) in wrow.chunks_mut(4).enumerate() {
                    // SAFETY: 0 ≤ base ≤ (rows.len() − 3) − P (clamped above), and the values
                    // read are `base + 4 g ..= base + 4 g + 3 ≤ base + P + 2` (as `4 g < P`).
                    let ld = |i: usize| unsafe { _mm_loadu_ps(wrows.add(b[i] as usize + 4 * g)) };
                    let r0 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(ld(0)), ld(4));
                    let r1 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(ld(1)), ld(5));
                    let r2 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(ld(2)), ld(6));
                    let r3 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(ld(3)), ld(7));
                    let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
                    let (t2, t3) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
                    let pd = _mm256_castps_pd;
                    let all = [
                        _mm256_castpd_ps(_mm256_unpacklo_pd(pd(t0), pd(t2))),
                        _mm256_castpd_ps(_mm256_unpackhi_pd(pd(t0), pd(t2))),
                        _mm256_castpd_ps(_mm256_unpacklo_pd(pd(t1), pd(t3))),
                        _mm256_castpd_ps(_mm256_unpackhi_pd(pd(t1), pd(t3))),
                    ];
                    let m = cols.len();
                    cols.copy_from_slice(&all[..m]);
                }
                let (mut n2, mut d2) = (zero, zero);
                for j in 0..P {
                    let f = fs[v][j];
                    let wt = _mm256_mul_ps(f, wrow[j]);
                    n2 = _mm256_add_ps(n2, _mm256_mul_ps(wt, vs[v][j]));
                    d2 = _mm256_add_ps(d2, wt);
                }
                // `refined`: the refined value where some frame voted and E₀ is a number.
                let e0 = e0s[v];
                let x = _mm256_div_ps(n2, d2);
                let ok = _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GT_OQ>(d2, zero),
                    _mm256_cmp_ps::<_CMP_ORD_Q>(e0, e0),
                );
                let r = exp2(_mm256_blendv_ps(e0, x, ok));
                let o = &mut out[s..s + 8];
                // SAFETY: `o` is 8 writable `f32`s.
                unsafe { _mm256_storeu_ps(o.as_mut_ptr(), r) };
            }
            s0 += 8 * count;
        }
        n
    }

    /// Per lane of each of the three vectors of a step (its third `q`): its channel's constants.
    struct Consts {
        start: [__m256i; 3],
        off: [__m256; 3],
        last: [__m256; 3],
        /// The last row's first entry: every row index is clamped to `0 ..= max_base` (a
        /// clamped bin is in range by construction; the clamp keeps every read in bounds
        /// whatever it holds).
        max_base: __m256i,
    }

    impl Consts {
        #[target_feature(enable = "avx2")]
        fn new<const P: usize>(k: &Fused) -> Self {
            let lane = |q: usize, f: &dyn Fn(usize) -> i32| {
                let v: [i32; 8] = std::array::from_fn(|l| f((8 * q + l) % 3));
                _mm256_setr_epi32(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7])
            };
            let lane_f = |q: usize, f: &dyn Fn(usize) -> f32| {
                let v: [f32; 8] = std::array::from_fn(|l| f((8 * q + l) % 3));
                _mm256_setr_ps(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7])
            };
            Self {
                start: std::array::from_fn(|q| lane(q, &|c| k.start[c])),
                off: std::array::from_fn(|q| lane_f(q, &|c| k.off[c])),
                last: std::array::from_fn(|q| lane_f(q, &|c| k.last[c])),
                max_base: _mm256_set1_epi32((k.rows.len() - 3 - P) as i32),
            }
        }
    }

    /// The first stage for the eight samples from `s` (the `Q`-th vector of a step, `s` a
    /// multiple of 8): the hat's `log2 E₀` and its weight row's first entry in `k.rows`; every
    /// frame's votes and observed-code factors into `vs` and `fs` (written in place: returned,
    /// the arrays were copied, 30 % more instructions at 9 frames).
    ///
    /// # Safety
    /// `s + 8 ≤ codes[j].len()` for every frame `j` (the codes are read unchecked).
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn hat_stage<const P: usize, const Q: usize>(
        k: &Fused,
        codes: &[&[u8]; P],
        s: usize,
        c: &Consts,
        vs: &mut [__m256; P],
        fs: &mut [__m256; P],
    ) -> (__m256, __m256i) {
        let zero = _mm256_setzero_ps();
        let (mut num, mut den, mut gn, mut gd) = (zero, zero, zero, zero);
        for j in 0..P {
            // SAFETY: the caller's promise, `s + 8 ≤ codes[j].len()`.
            let b = unsafe { codes[j].as_ptr().add(s) };
            // SAFETY: eight readable bytes at `b` (`movq` needs no alignment).
            let z = _mm256_cvtepu8_epi32(unsafe { _mm_loadl_epi64(b.cast()) });
            let Ok(table) = <&[[f32; 2]; 768]>::try_from(&k.votes[j * 768..j * 768 + 768]) else {
                unreachable!("a frame's entries")
            };
            // SAFETY: as above.
            let (vj, fj) = unsafe { lookup::<Q>(table, b) };
            (vs[j], fs[j]) = (vj, fj);
            let w = hat_weight::<P>(j, z);
            let wv = _mm256_mul_ps(w, vj);
            // The hat's sums, three frames to a group as the scalar path adds them.
            if j % 3 == 0 {
                (gd, gn) = (w, wv);
            } else {
                gd = _mm256_add_ps(gd, w);
                gn = _mm256_add_ps(gn, wv);
            }
            if j % 3 == 2 || j + 1 == P {
                if j < 3 {
                    (num, den) = (gn, gd);
                } else {
                    num = _mm256_add_ps(num, gn);
                    den = _mm256_add_ps(den, gd);
                }
            }
        }
        // The hat's log2 E₀ and its weight row (`floor_bin` of refine.rs: x is clamped to
        // `0 ..= last < 2²²`, so its floor is its truncation, and `max` makes NaN 0 as there).
        let e0 = _mm256_div_ps(num, den);
        let bins = _mm256_set1_ps(super::super::refine::BINS_PER_STOP);
        let x = _mm256_sub_ps(_mm256_mul_ps(e0, bins), c.off[Q]);
        let x = _mm256_min_ps(_mm256_max_ps(x, zero), c.last[Q]);
        let at = _mm256_add_epi32(c.start[Q], _mm256_cvttps_epi32(x));
        let base = _mm256_mullo_epi32(at, _mm256_set1_epi32(P as i32));
        let base = _mm256_max_epi32(_mm256_min_epi32(base, c.max_base), _mm256_setzero_si256());
        (e0, base)
    }

    /// The votes and factors `table[256 c + z]` of eight codes `z` whose lanes are the `Q`-th
    /// vector of a step (lane `l`'s channel `c = (8 Q + l) % 3`, a constant): each entry by
    /// one 8-byte load from the code's byte (a zero-extending byte load and a load at a
    /// constant offset), two to a 16-byte half, split by two shuffles. The byte loads are
    /// volatile so that the compiler keeps them: otherwise it reads the eight codes as one
    /// `u64` and extracts each by shifts (two or three instructions a lane more). Before, the
    /// indices were formed by a vector add and stored for scalar loads to read back.
    ///
    /// # Safety
    /// `z` points to eight readable bytes.
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn lookup<const Q: usize>(table: &[[f32; 2]; 768], z: *const u8) -> (__m256, __m256) {
        let base = table.as_ptr();
        // SAFETY: `z + l` is readable (the caller's promise, `l < 8`), and
        // `256 c + z ≤ 2 · 256 + 255 = 767` is within the table.
        let at = |l: usize| unsafe {
            base.add(256 * ((8 * Q + l) % 3) + z.add(l).read_volatile() as usize)
        };
        let at = |l: usize| at(l).cast::<f64>();
        // SAFETY: each pointer is to an entry of two `f32`s, eight readable bytes (`movsd` and
        // `movhpd` need no alignment).
        let pair = |l: usize| unsafe { _mm_loadh_pd(_mm_load_sd(at(l)), at(l + 1)) };
        let half = |l: usize, h: usize| {
            _mm256_castpd_ps(_mm256_insertf128_pd::<1>(
                _mm256_castpd128_pd256(pair(l)),
                pair(h),
            ))
        };
        // a = [v0 f0 v1 f1 | v4 f4 v5 f5], b = [v2 f2 v3 f3 | v6 f6 v7 f7].
        let (a, b) = (half(0, 4), half(2, 6));
        (
            _mm256_shuffle_ps::<0b10_00_10_00>(a, b),
            _mm256_shuffle_ps::<0b11_01_11_01>(a, b),
        )
    }

    /// `super::hat_weight` for eight codes.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn hat_weight<const P: usize>(j: usize, z: __m256i) -> __m256 {
        let full = _mm256_set1_ps(super::super::hat::W_MAX);
        let mut w = _mm256_cvtepi32_ps(_mm256_min_epi32(
            z,
            _mm256_sub_epi32(_mm256_set1_epi32(255), z),
        ));
        if j == 0 {
            let high = _mm256_cmpgt_epi32(z, _mm256_set1_epi32(127));
            w = _mm256_blendv_ps(w, full, _mm256_castsi256_ps(high));
        }
        if j + 1 == P {
            let low = _mm256_cmpgt_epi32(_mm256_set1_epi32(128), z);
            w = _mm256_blendv_ps(w, full, _mm256_castsi256_ps(low));
        }
        if j == 0 {
            w = _mm256_max_ps(w, _mm256_set1_ps(super::super::hat::W_FLOOR));
        }
        w
    }

    /// [`crate::fastmath::exp2`] for eight values: the same operations in the same order.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn exp2(x: __m256) -> __m256 {
        // `x.clamp(−L, L)`: NaN stays NaN (`maxps`/`minps` return their second operand then).
        let x = _mm256_max_ps(_mm256_set1_ps(-EXP2_LIMIT), x);
        let x = _mm256_min_ps(_mm256_set1_ps(EXP2_LIMIT), x);
        let magic = _mm256_set1_ps(EXP2_MAGIC);
        let t = _mm256_add_ps(x, magic);
        let k = _mm256_sub_epi32(_mm256_castps_si256(t), _mm256_castps_si256(magic));
        let f = _mm256_sub_ps(x, _mm256_sub_ps(t, magic));
        let c = EXP2_C.map(|v| _mm256_set1_ps(v));
        let p = _mm256_add_ps(c[4], _mm256_mul_ps(f, c[5]));
        let p = _mm256_add_ps(c[3], _mm256_mul_ps(f, p));
        let p = _mm256_add_ps(c[2], _mm256_mul_ps(f, p));
        let p = _mm256_add_ps(c[1], _mm256_mul_ps(f, p));
        let p = _mm256_add_ps(c[0], _mm256_mul_ps(f, p));
        let scale = _mm256_slli_epi32::<23>(_mm256_add_epi32(k, _mm256_set1_epi32(127)));
        _mm256_mul_ps(p, _mm256_castsi256_ps(scale))
    }
}

#[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
mod simd128 {
    //! The kernel of the `avx2` module for WebAssembly's SIMD128: four samples a vector, the
    //! same operations in the same order (wasm has no fused multiply-add without
    //! relaxed-simd, which is not enabled). Where the instructions differ the NaN rules are
    //! matched: `f32x4.pmax(a, b)` is `if a < b { b } else { a }` and `pmin(a, b)` is
    //! `if b < a { b } else { a }`, exactly the selects of `floor_bin` and `f32::clamp`.
    use super::{Fused, MAX_FRAMES, STEP};
    use crate::fastmath::{EXP2_C, EXP2_LIMIT, EXP2_MAGIC};
    use core::arch::wasm32::*;

    /// [`Fused::row`] for SIMD128.
    pub(super) fn row(k: &Fused, rows: &[&[u8]], out: &mut [f32]) -> usize {
        match rows.len() {
            1 => run::<1>(k, rows, out),
            2 => run::<2>(k, rows, out),
            3 => run::<3>(k, rows, out),
            4 => run::<4>(k, rows, out),
            5 => run::<5>(k, rows, out),
            6 => run::<6>(k, rows, out),
            7 => run::<7>(k, rows, out),
            8 => run::<8>(k, rows, out),
            9 => run::<9>(k, rows, out),
            _ => 0,
        }
    }

    /// The kernel for `P` frames: as `avx2::run`, in blocks of vectors, the hat stage of
    /// every vector of a block and then every vector's refinement.
    #[inline]
    fn run<const P: usize>(k: &Fused, rows: &[&[u8]], out: &mut [f32]) -> usize {
        const { assert!(P <= MAX_FRAMES) };
        let n = rows.iter().map(|r| r.len()).fold(out.len(), usize::min) / STEP * STEP;
        let codes: [&[u8]; P] = std::array::from_fn(|j| &rows[j][..n]);
        let out = &mut out[..n];
        let consts = Consts::new::<P>(k);
        let zero = f32x4_splat(0.0);
        let wrows = k.rows.as_ptr();
        // Vectors per block, a multiple of three (a block starts where a step's channels do).
        const BLOCK: usize = 12;
        let mut e0s = [zero; BLOCK];
        let mut bases = [zero; BLOCK];
        let mut vs = [[zero; P]; BLOCK];
        let mut fs = [[zero; P]; BLOCK];
        let mut s0 = 0;
        while s0 < n {
            // `s0` and `n` are multiples of STEP (24 = six vectors), so `count` is a multiple
            // of three and each third of three vectors has its lanes' channels fixed.
            let count = ((n - s0) / 4).min(BLOCK);
            debug_assert!(s0.is_multiple_of(STEP) && count.is_multiple_of(3));
            let mut v = 0;
            while v < count {
                let s = s0 + 4 * v;
                let c = &consts;
                // SAFETY: `s + 12 ≤ n`, every frame's row length (`count` vectors remain).
                unsafe {
                    (e0s[v], bases[v]) = hat_stage::<P, 0>(k, &codes, s, c, &mut vs[v], &mut fs[v]);
                    (e0s[v + 1], bases[v + 1]) =
                        hat_stage::<P, 1>(k, &codes, s + 4, c, &mut vs[v + 1], &mut fs[v + 1]);
                    (e0s[v + 2], bases[v + 2]) =
                        hat_stage::<P, 2>(k, &codes, s + 8, c, &mut vs[v + 2], &mut fs[v + 2]);
                }
                v += 3;
            }
            for v in 0..count {
                let s = s0 + 4 * v;
                // Every frame's weight for the 4 samples: four frames at a time by one 16-byte
                // load a sample and a 4 × 4 transpose.
                let bv = bases[v];
                let b = [
                    i32x4_extract_lane::<0>(bv) as usize,
                    i32x4_extract_lane::<1>(bv) as usize,
                    i32x4_extract_lane::<2>(bv) as usize,
                    i32x4_extract_lane::<3>(bv) as usize,
                ];
                let mut wrow = [zero; P];
                for (g, cols) in wrow.chunks_mut(4).enumerate() {
                    // SAFETY: 0 ≤ base ≤ (rows.len() − 3) − P (clamped in `hat_stage`), and the
                    // values read are `base + 4 g ..= base + 4 g + 3 ≤ base + P + 2` (`4 g < P`).
                    let ld = |i: usize| unsafe {
                        wrows.add(b[i] + 4 * g).cast::<v128>().read_unaligned()
                    };
                    let (r0, r1, r2, r3) = (ld(0), ld(1), ld(2), ld(3));
                    let (t0, t1) = (
                        i32x4_shuffle::<0, 4, 1, 5>(r0, r1),
                        i32x4_shuffle::<2, 6, 3, 7>(r0, r1),
                    );
                    let (t2, t3) = (
                        i32x4_shuffle::<0, 4, 1, 5>(r2, r3),
                        i32x4_shuffle::<2, 6, 3, 7>(r2, r3),
                    );
                    let all = [
                        i64x2_shuffle::<0, 2>(t0, t2),
                        i64x2_shuffle::<1, 3>(t0, t2),
                        i64x2_shuffle::<0, 2>(t1, t3),
                        i64x2_shuffle::<1, 3>(t1, t3),
                    ];
                    let m = cols.len();
                    cols.copy_from_slice(&all[..m]);
                }
                let (mut n2, mut d2) = (zero, zero);
                for j in 0..P {
                    let wt = f32x4_mul(fs[v][j], wrow[j]);
                    n2 = f32x4_add(n2, f32x4_mul(wt, vs[v][j]));
                    d2 = f32x4_add(d2, wt);
                }
                // `refined`: the refined value where some frame voted and E₀ is a number.
                let e0 = e0s[v];
                let x = f32x4_div(n2, d2);
                let ok = v128_and(f32x4_gt(d2, zero), f32x4_eq(e0, e0));
                let r = exp2(v128_bitselect(x, e0, ok));
                let o = &mut out[s..s + 4];
                // SAFETY: `o` is 4 writable `f32`s.
                unsafe { o.as_mut_ptr().cast::<v128>().write_unaligned(r) };
            }
            s0 += 4 * count;
        }
        n
    }

    /// Per lane of each of the three vectors of twelve samples (its third `q`): its
    /// channel's constants.
    struct Consts {
        start: [v128; 3],
        off: [v128; 3],
        last: [v128; 3],
        /// The last row's first entry: every row index is clamped to `0 ..= max_base`.
        max_base: v128,
    }

    impl Consts {
        fn new<const P: usize>(k: &Fused) -> Self {
            let lane = |q: usize, f: &dyn Fn(usize) -> i32| {
                let v: [i32; 4] = std::array::from_fn(|l| f((4 * q + l) % 3));
                i32x4(v[0], v[1], v[2], v[3])
            };
            let lane_f = |q: usize, f: &dyn Fn(usize) -> f32| {
                let v: [f32; 4] = std::array::from_fn(|l| f((4 * q + l) % 3));
                f32x4(v[0], v[1], v[2], v[3])
            };
            Self {
                start: std::array::from_fn(|q| lane(q, &|c| k.start[c])),
                off: std::array::from_fn(|q| lane_f(q, &|c| k.off[c])),
                last: std::array::from_fn(|q| lane_f(q, &|c| k.last[c])),
                max_base: i32x4_splat((k.rows.len() - 3 - P) as i32),
            }
        }
    }

    /// The first stage for the four samples from `s` (the `Q`-th vector of twelve samples,
    /// `s` a multiple of 4): the hat's `log2 E₀` and its weight row's first entry in `k.rows`
    /// (as `i32` lanes); every frame's votes and observed-code factors into `vs` and `fs`.
    ///
    /// # Safety
    /// `s + 4 ≤ codes[j].len()` for every frame `j` (the codes are read unchecked).
    #[inline]
    unsafe fn hat_stage<const P: usize, const Q: usize>(
        k: &Fused,
        codes: &[&[u8]; P],
        s: usize,
        c: &Consts,
        vs: &mut [v128; P],
        fs: &mut [v128; P],
    ) -> (v128, v128) {
        let zero = f32x4_splat(0.0);
        let (mut num, mut den, mut gn, mut gd) = (zero, zero, zero, zero);
        for j in 0..P {
            // SAFETY: the caller's promise, `s + 4 ≤ codes[j].len()`.
            let b = unsafe { codes[j].as_ptr().add(s) };
            // SAFETY: four readable bytes at `b`; the low four bytes of the splat, widened.
            let word = unsafe { b.cast::<u32>().read_unaligned() };
            let z = u32x4_extend_low_u16x8(u16x8_extend_low_u8x16(u32x4_splat(word)));
            let Ok(table) = <&[[f32; 2]; 768]>::try_from(&k.votes[j * 768..j * 768 + 768]) else {
                unreachable!("a frame's entries")
            };
            // SAFETY: as above.
            let (vj, fj) = unsafe { lookup::<Q>(table, b) };
            (vs[j], fs[j]) = (vj, fj);
            let w = hat_weight::<P>(j, z);
            let wv = f32x4_mul(w, vj);
            // The hat's sums, three frames to a group as the scalar path adds them.
            if j % 3 == 0 {
                (gd, gn) = (w, wv);
            } else {
                gd = f32x4_add(gd, w);
                gn = f32x4_add(gn, wv);
            }
            if j % 3 == 2 || j + 1 == P {
                if j < 3 {
                    (num, den) = (gn, gd);
                } else {
                    num = f32x4_add(num, gn);
                    den = f32x4_add(den, gd);
                }
            }
        }
        // The hat's log2 E₀ and its weight row (`floor_bin` of refine.rs: `pmax(0, x)` is
        // `if 0 < x { x } else { 0 }` (NaN gives 0) and `pmin(top, x)` `if x < top { x } else
        // { top }`, its selects; x is then in `0 ..= last < 2²²`, its floor its truncation).
        let e0 = f32x4_div(num, den);
        let bins = f32x4_splat(super::super::refine::BINS_PER_STOP);
        let x = f32x4_sub(f32x4_mul(e0, bins), c.off[Q]);
        let x = f32x4_pmin(c.last[Q], f32x4_pmax(zero, x));
        let at = i32x4_add(c.start[Q], i32x4_trunc_sat_f32x4(x));
        let base = i32x4_mul(at, i32x4_splat(P as i32));
        let base = i32x4_max(i32x4_min(base, c.max_base), i32x4_splat(0));
        (e0, base)
    }

    /// The votes and factors `table[256 c + z]` of four codes `z` whose lanes are the `Q`-th
    /// vector of twelve samples (lane `l`'s channel `c = (4 Q + l) % 3`, a constant): each
    /// entry by one 8-byte load, two to a vector, split by two shuffles.
    ///
    /// # Safety
    /// `z` points to four readable bytes.
    #[inline]
    unsafe fn lookup<const Q: usize>(table: &[[f32; 2]; 768], z: *const u8) -> (v128, v128) {
        let base = table.as_ptr();
        // SAFETY: `z + l` is readable (the caller's promise, `l < 4`), and
        // `256 c + z ≤ 2 · 256 + 255 = 767` is within the table; an entry is eight bytes.
        let at = |l: usize| unsafe {
            base.add(256 * ((4 * Q + l) % 3) + *z.add(l) as usize)
                .cast::<u64>()
                .read_unaligned()
        };
        // a = [v0 f0 v1 f1], b = [v2 f2 v3 f3].
        let (a, b) = (u64x2(at(0), at(1)), u64x2(at(2), at(3)));
        (
            i32x4_shuffle::<0, 2, 4, 6>(a, b),
            i32x4_shuffle::<1, 3, 5, 7>(a, b),
        )
    }

    /// `super::hat_weight` for four codes.
    #[inline]
    fn hat_weight<const P: usize>(j: usize, z: v128) -> v128 {
        let full = f32x4_splat(super::super::hat::W_MAX);
        let mut w = f32x4_convert_i32x4(i32x4_min(z, i32x4_sub(i32x4_splat(255), z)));
        if j == 0 {
            let high = i32x4_gt(z, i32x4_splat(127));
            w = v128_bitselect(full, w, high);
        }
        if j + 1 == P {
            let low = i32x4_gt(i32x4_splat(128), z);
            w = v128_bitselect(full, w, low);
        }
        if j == 0 {
            // `w` is a number: `pmax` is `max`.
            w = f32x4_pmax(w, f32x4_splat(super::super::hat::W_FLOOR));
        }
        w
    }

    /// [`crate::fastmath::exp2`] for four values: the same operations in the same order.
    #[inline]
    fn exp2(x: v128) -> v128 {
        // `x.clamp(−L, L)`, its two selects: `if x < −L { −L } else { x }`, then
        // `if L < x { L } else { x }`; NaN stays NaN.
        let x = f32x4_pmax(x, f32x4_splat(-EXP2_LIMIT));
        let x = f32x4_pmin(x, f32x4_splat(EXP2_LIMIT));
        let magic = f32x4_splat(EXP2_MAGIC);
        let t = f32x4_add(x, magic);
        let k = i32x4_sub(t, magic);
        let f = f32x4_sub(x, f32x4_sub(t, magic));
        let c = EXP2_C.map(|v| f32x4_splat(v));
        let p = f32x4_add(c[4], f32x4_mul(f, c[5]));
        let p = f32x4_add(c[3], f32x4_mul(f, p));
        let p = f32x4_add(c[2], f32x4_mul(f, p));
        let p = f32x4_add(c[1], f32x4_mul(f, p));
        let p = f32x4_add(c[0], f32x4_mul(f, p));
        let scale = i32x4_shl(i32x4_add(k, i32x4_splat(127)), 23);
        f32x4_mul(p, scale)
    }
}

#[cfg(test)]
pub(super) mod tests {
    use crate::bracket::{Exposure, Frame, Pixels};
    use crate::merge::{merge, MergeOptions, Weighting};
    use crate::noise::NoiseModel;
    use crate::response::{Response, LEVELS};
    use std::cell::Cell;

    thread_local! {
        /// Set, this thread's merges take the scalar path.
        pub(in crate::merge) static SCALAR: Cell<bool> = const { Cell::new(false) };
    }

    /// Random 8-bit frames, a third of the codes at the black level, the top fade or a bound.
    fn frames(p: usize, w: usize, h: usize, seed: u64) -> Vec<Frame> {
        let mut state = seed | 1;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        (0..p)
            .map(|j| {
                let pixels = (0..w * h * 3)
                    .map(|_| match next() % 9 {
                        0 => 0,
                        1 => 255,
                        2 => 240 + (next() % 16) as u8,
                        3 => (next() % 16) as u8,
                        _ => next() as u8,
                    })
                    .collect();
                Frame {
                    name: format!("f{j}"),
                    width: w,
                    height: h,
                    pixels: Pixels::U8(pixels),
                    exposure: Exposure {
                        time_s: 2f64.powf(1.5 * j as f64) / 100.0,
                        iso: None,
                        f_number: None,
                    },
                }
            })
            .collect()
    }

    #[test]
    fn the_vector_kernel_gives_the_scalar_paths_bits() {
        if !super::available() {
            println!("skipped: this CPU has no AVX2, so only the scalar path exists");
            return;
        }
        let r = Response::from_curves([0.9, 1.0, 1.1].map(|a| {
            (0..LEVELS)
                .map(|z| a * ((z as f64 + 0.5) / 128.5).ln())
                .collect::<Vec<_>>()
        }))
        .unwrap();
        let model = NoiseModel::default();
        for p in 1..=super::MAX_FRAMES + 1 {
            for black in [0u8, 9] {
                // 37 pixels a row: four steps of eight pixels and a scalar tail of five.
                let fs = frames(p, 37, 11, 7 + p as u64 + black as u64);
                let lt: Vec<f64> = fs.iter().map(|f| f.exposure.relative().ln()).collect();
                let g = |c: usize, v: usize| r.curve(c)[v];
                let refine = super::Refine::<256>::new(&lt, &r, &model, black, g);
                let hat = super::super::hat::Tables::<256>::new(
                    &lt,
                    |j, _c, z| super::super::hat::weight(z, j, p, Weighting::Hat),
                    g,
                );
                let fused = super::Fused::new(&refine, |j, c, z| hat.entry(j, c, z));
                assert_eq!(
                    fused.is_some(),
                    p <= super::MAX_FRAMES,
                    "{p} frames, black {black}: the kernel should run up to {} frames",
                    super::MAX_FRAMES
                );
                let o = MergeOptions {
                    weighting: Weighting::Noise,
                    noise: Some(model),
                    black_level: black,
                    ..Default::default()
                };
                let vector = merge(&fs, &r, &o).unwrap().radiance.data;
                SCALAR.with(|s| s.set(true));
                let scalar = merge(&fs, &r, &o).unwrap().radiance.data;
                SCALAR.with(|s| s.set(false));
                let differ = vector
                    .iter()
                    .zip(&scalar)
                    .filter(|(a, b)| a.to_bits() != b.to_bits())
                    .count();
                assert_eq!(
                    differ, 0,
                    "{p} frames, black {black}: {differ} samples differ"
                );
            }
        }
    }
}
