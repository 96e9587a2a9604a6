/*
 * Copyright (c) 2023.
 *
 * This software is free software;
 *
 * You can redistribute it or modify it under terms of the MIT, Apache License or Zlib license
 */

//! WebAssembly SIMD (simd128) IDCT: the integer IDCT of `scalar.rs`, eight 32-bit lanes per
//! row held in two `i32x4` vectors, ported from the NEON and AVX2 versions (same arithmetic,
//! same order, wrapping 32-bit operations), so the output is bit-identical to the scalar code.
//!
//! Added to the skydome vendored copy of zune-jpeg 0.5.15 (see PATCHED.md); compiled only for
//! `wasm32` with the `simd128` target feature enabled at build time, where these functions are
//! always available (a wasm engine without SIMD refuses the whole module).

#![cfg(all(target_arch = "wasm32", target_feature = "simd128"))]

use core::arch::wasm32::*;
use core::ops::{Add, Mul, Sub};

const SCALE_BITS: i32 = 512 + 65536 + (128 << 17);

/// One row of eight `i32` coefficients: lanes 0–3 in `lo`, 4–7 in `hi`.
#[derive(Clone, Copy)]
struct Row {
    lo: v128,
    hi: v128
}

impl Row {
    #[inline(always)]
    fn load(src: &[i32; 64], start: usize) -> Row {
        Row { lo: load_i32x4(src, start), hi: load_i32x4(src, start + 4) }
    }

    #[inline(always)]
    fn or(self, o: Row) -> Row {
        Row { lo: v128_or(self.lo, o.lo), hi: v128_or(self.hi, o.hi) }
    }

    #[inline(always)]
    fn all_zero(self) -> bool {
        !v128_any_true(v128_or(self.lo, self.hi))
    }
}

/// Four `i32` lanes with the scalar code's wrapping operators, so the passes below read as
/// the scalar code.
#[derive(Clone, Copy)]
struct V(v128);

impl V {
    #[inline(always)]
    fn shl<const N: u32>(self) -> V {
        V(i32x4_shl(self.0, N))
    }

    #[inline(always)]
    fn shra<const N: u32>(self) -> V {
        V(i32x4_shr(self.0, N))
    }
}

impl Add for V {
    type Output = V;
    #[inline(always)]
    fn add(self, o: V) -> V {
        V(i32x4_add(self.0, o.0))
    }
}

impl Add<i32> for V {
    type Output = V;
    #[inline(always)]
    fn add(self, o: i32) -> V {
        V(i32x4_add(self.0, i32x4_splat(o)))
    }
}

impl Sub for V {
    type Output = V;
    #[inline(always)]
    fn sub(self, o: V) -> V {
        V(i32x4_sub(self.0, o.0))
    }
}

impl Mul<i32> for V {
    type Output = V;
    #[inline(always)]
    fn mul(self, o: i32) -> V {
        V(i32x4_mul(self.0, i32x4_splat(o)))
    }
}

/// Four `i32` from `src[start..start + 4]` (bounds-checked).
#[inline(always)]
fn load_i32x4(src: &[i32], start: usize) -> v128 {
    let s: &[i32; 4] = src[start..start + 4].try_into().unwrap();
    // SAFETY: `s` is 16 readable bytes; wasm's v128.load has no alignment requirement.
    unsafe { v128_load(s.as_ptr().cast()) }
}

/// Stores eight `i16` at `out[pos..pos + 8]`, or nowhere when the slice is too short (as the
/// scalar code, "to prevent some bad images from crashing").
#[inline(always)]
fn store_i16x8(out: &mut [i16], pos: usize, v: v128) {
    if let Some(dst) = out.get_mut(pos..pos + 8) {
        let dst: &mut [i16; 8] = dst.try_into().unwrap();
        // SAFETY: `dst` is 16 writable bytes; wasm's v128.store has no alignment requirement.
        unsafe { v128_store(dst.as_mut_ptr().cast(), v) }
    }
}

/// Transposes the 4×4 block of `i32` lanes held in `a`, `b`, `c`, `d`.
#[inline(always)]
fn transpose4(a: v128, b: v128, c: v128, d: v128) -> [v128; 4] {
    // a0 b0 a1 b1 / a2 b2 a3 b3 / c0 d0 c1 d1 / c2 d2 c3 d3
    let ab_lo = i32x4_shuffle::<0, 4, 1, 5>(a, b);
    let ab_hi = i32x4_shuffle::<2, 6, 3, 7>(a, b);
    let cd_lo = i32x4_shuffle::<0, 4, 1, 5>(c, d);
    let cd_hi = i32x4_shuffle::<2, 6, 3, 7>(c, d);
    [
        i64x2_shuffle::<0, 2>(ab_lo, cd_lo),
        i64x2_shuffle::<1, 3>(ab_lo, cd_lo),
        i64x2_shuffle::<0, 2>(ab_hi, cd_hi),
        i64x2_shuffle::<1, 3>(ab_hi, cd_hi)
    ]
}

/// Transposes an 8×8 block held as two halves of four lanes, `lo[k]` (lanes 0–3 of vector
/// `k`) and `hi[k]` (lanes 4–7), into the same layout.
#[inline(always)]
fn transpose8(lo: &[v128; 8], hi: &[v128; 8]) -> ([v128; 8], [v128; 8]) {
    let a = transpose4(lo[0], lo[1], lo[2], lo[3]);
    let b = transpose4(lo[4], lo[5], lo[6], lo[7]);
    let c = transpose4(hi[0], hi[1], hi[2], hi[3]);
    let d = transpose4(hi[4], hi[5], hi[6], hi[7]);
    (
        [a[0], a[1], a[2], a[3], c[0], c[1], c[2], c[3]],
        [b[0], b[1], b[2], b[3], d[0], d[1], d[2], d[3]]
    )
}

/// One pass of the 8-point IDCT over four lanes (`scalar::idct_int`'s loop bodies): `r[k]`
/// holds input `k` of four independent transforms; `bias` is the rounding (and level shift)
/// added before the shift by `SHIFT`.
///
/// Four lanes at a time, not eight: the eight-lane version needs sixteen vectors for the block
/// alone and V8 spills them on x86-64 (16 vector registers), which made it slower than the
/// scalar code.
#[inline(always)]
fn pass<const SHIFT: u32>(r: [v128; 8], bias: i32) -> [v128; 8] {
    let [row0, row1, row2, row3, row4, row5, row6, row7] = r.map(V);
    // even part
    let p1 = (row2 + row6) * 2217;

    let t2 = p1 + row6 * -7567;
    let t3 = p1 + row2 * 3135;

    let t0 = (row0 + row4).shl::<12>();
    let t1 = (row0 - row4).shl::<12>();

    let x0 = t0 + t3 + bias;
    let x3 = t0 - t3 + bias;
    let x1 = t1 + t2 + bias;
    let x2 = t1 - t2 + bias;

    // odd part
    let p3 = row7 + row3;
    let p4 = row5 + row1;
    let p1 = row7 + row1;
    let p2 = row5 + row3;
    let p5 = (p3 + p4) * 4816;

    let t0 = row7 * 1223;
    let t1 = row5 * 8410;
    let t2 = row3 * 12586;
    let t3 = row1 * 6149;

    let p1 = p5 + p1 * -3685;
    let p2 = p5 + p2 * -10497;
    let p3 = p3 * -8034;
    let p4 = p4 * -1597;

    let t3 = t3 + (p1 + p4);
    let t2 = t2 + (p2 + p3);
    let t1 = t1 + (p2 + p4);
    let t0 = t0 + (p1 + p3);

    [
        (x0 + t3).shra::<SHIFT>().0,
        (x1 + t2).shra::<SHIFT>().0,
        (x2 + t1).shra::<SHIFT>().0,
        (x3 + t0).shra::<SHIFT>().0,
        (x3 - t0).shra::<SHIFT>().0,
        (x2 - t1).shra::<SHIFT>().0,
        (x1 - t2).shra::<SHIFT>().0,
        (x0 - t3).shra::<SHIFT>().0
    ]
}

/// One pass of the 4-point-input IDCT over four lanes (`scalar::idct4x4`'s loop bodies): only
/// inputs 0–3 are non-zero; `bias` as in [`pass`].
#[inline(always)]
fn pass4<const SHIFT: u32>(r: [v128; 4], bias: i32) -> [v128; 8] {
    let [i0, i1, i2, i3] = r.map(V);
    let t0 = i0.shl::<12>() + bias;
    let p1 = i2 * 2217;
    let p3 = i2 * 5352;
    let x0 = t0 + p3;
    let x1 = t0 + p1;
    let x2 = t0 - p1;
    let x3 = t0 - p3;
    // odd part
    let p5 = (i3 + i1) * 4816;
    let p1 = p5 + i1 * -3685;
    let p2 = p5 + i3 * -10497;
    let t3 = p5 + i1 * 867;
    let t2 = p5 + i3 * -5945;
    let t1 = p2 + i1 * -1597;
    let t0 = p1 + i3 * -8034;
    [
        (x0 + t3).shra::<SHIFT>().0,
        (x1 + t2).shra::<SHIFT>().0,
        (x2 + t1).shra::<SHIFT>().0,
        (x3 + t0).shra::<SHIFT>().0,
        (x3 - t0).shra::<SHIFT>().0,
        (x2 - t1).shra::<SHIFT>().0,
        (x1 - t2).shra::<SHIFT>().0,
        (x0 - t3).shra::<SHIFT>().0
    ]
}

/// Packs the finished block (row `k` in `lo[k]`, `hi[k]`) to `i16` (saturating), clamps to
/// 0..=255 and stores its rows `stride` apart, as the scalar `clamp(x >> 17)`.
#[inline(always)]
fn store_block(out: &mut [i16], stride: usize, lo: &[v128; 8], hi: &[v128; 8]) {
    let zero = i16x8_splat(0);
    let max = i16x8_splat(255);
    for k in 0..8 {
        let packed = i16x8_narrow_i32x4(lo[k], hi[k]);
        store_i16x8(out, k * stride, i16x8_min(i16x8_max(packed, zero), max));
    }
}

/// Fills the 8×8 output block with the DC value: the IDCT of a block whose 63 AC coefficients
/// are zero (`scalar::idct_int_1x1`).
pub fn idct_wasm_1x1(in_vector: &mut [i32; 64], out_vector: &mut [i16], stride: usize) {
    let coeff = (in_vector[0].wrapping_add(4).wrapping_add(1024) >> 3).clamp(0, 255) as i16;
    let v = i16x8_splat(coeff);
    // The decoder always passes room for eight rows; rows that would not fit are skipped (as the
    // full IDCT's, "to prevent some bad images from crashing") where the scalar code panics.
    for row in 0..8 {
        store_i16x8(out_vector, row * stride, v);
    }
}

/// The full 8×8 IDCT (`scalar::idct_int`). Leaves `in_vector` unchanged.
pub fn idct_wasm(in_vector: &mut [i32; 64], out_vector: &mut [i16], stride: usize) {
    let r: [Row; 8] = core::array::from_fn(|k| Row::load(in_vector, 8 * k));
    // All 63 AC coefficients zero: the DC value everywhere (the scalar code's shortcut).
    let ac0 = Row { lo: load_i32x4(in_vector, 1), hi: load_i32x4(in_vector, 4) };
    let any = r[1].or(ac0).or(r[2]).or(r[3]).or(r[4]).or(r[5]).or(r[6]).or(r[7]);
    if any.all_zero() {
        return idct_wasm_1x1(in_vector, out_vector, stride);
    }
    // Columns: each lane is a column, the vectors are the coefficient rows (the scalar code's
    // vertical pass), columns 0–3 then 4–7.
    let lo = pass::<10>(r.map(|x| x.lo), 512);
    let hi = pass::<10>(r.map(|x| x.hi), 512);
    // Rows: transposed, each lane is a row, the vectors are the columns (its horizontal pass),
    // rows 0–3 then 4–7.
    let (lo, hi) = transpose8(&lo, &hi);
    let lo = pass::<17>(lo, SCALE_BITS);
    let hi = pass::<17>(hi, SCALE_BITS);
    let (lo, hi) = transpose8(&lo, &hi);
    store_block(out_vector, stride, &lo, &hi);
}

/// The IDCT of a block whose non-zero coefficients all lie in its upper-left 4×4
/// (`scalar::idct4x4`). Leaves `in_vector` unchanged, so its lower half stays zero as the
/// decoder's contract requires (`choose_idct_4x4_func`).
pub fn idct_wasm_4x4(in_vector: &mut [i32; 64], out_vector: &mut [i16], stride: usize) {
    // Columns 0–3 (the others are zero and only feed zero coefficients into the row pass,
    // which reads inputs 0–3 alone): coefficient rows 0–3 in, eight rows out.
    let cols = pass4::<10>(core::array::from_fn(|k| load_i32x4(in_vector, 8 * k)), 512);
    // Rows 0–3 and 4–7 of the transposed block, inputs (columns) 0–3 of each.
    let lo = transpose4(cols[0], cols[1], cols[2], cols[3]);
    let hi = transpose4(cols[4], cols[5], cols[6], cols[7]);
    let lo = pass4::<17>(lo, SCALE_BITS);
    let hi = pass4::<17>(hi, SCALE_BITS);
    let (lo, hi) = transpose8(&lo, &hi);
    store_block(out_vector, stride, &lo, &hi);
}
