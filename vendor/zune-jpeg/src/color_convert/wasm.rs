/*
 * Copyright (c) 2025.
 *
 * This software is free software;
 *
 * You can redistribute it or modify it under terms of the MIT, Apache License or Zlib license
 */

//! WebAssembly SIMD (simd128) YCbCr → RGB/RGBA conversion of 16 pixels: the arithmetic of
//! `scalar.rs` (14-bit BT.601 coefficients, 32-bit products, arithmetic shift, clamp to
//! 0..=255) in `i32x4` lanes, ported from the NEON version, so the output is bit-identical to
//! the scalar code.
//!
//! Added to the skydome vendored copy of zune-jpeg 0.5.15 (see PATCHED.md); compiled only for
//! `wasm32` with the `simd128` target feature enabled at build time.

#![cfg(all(target_arch = "wasm32", target_feature = "simd128"))]

use core::arch::wasm32::*;

use crate::color_convert::scalar::{CB_CF, CR_CF, C_G_CB_COEF_2, C_G_CR_COEF_1, YUV_RND, Y_CF};

/// Eight `i16` from a 16-element array, from `start` (0 or 8).
#[inline(always)]
fn load_i16x8(src: &[i16; 16], start: usize) -> v128 {
    let s: &[i16; 8] = src[start..start + 8].try_into().unwrap();
    // SAFETY: `s` is 16 readable bytes; wasm's v128.load has no alignment requirement.
    unsafe { v128_load(s.as_ptr().cast()) }
}

/// Stores 16 bytes at `out[pos..pos + 16]` (bounds-checked).
#[inline(always)]
fn store_u8x16(out: &mut [u8], pos: usize, v: v128) {
    let dst: &mut [u8; 16] = (&mut out[pos..pos + 16]).try_into().unwrap();
    // SAFETY: `dst` is 16 writable bytes; wasm's v128.store has no alignment requirement.
    unsafe { v128_store(dst.as_mut_ptr().cast(), v) }
}

/// `(acc + a * ca + b * cb) >> 14` for the low or high four `i16` lanes, in `i32`.
#[inline(always)]
fn channel(y0: v128, a: v128, ca: i16, b: v128, cb: i16, high: bool) -> v128 {
    let (pa, pb) = if high {
        (
            i32x4_extmul_high_i16x8(a, i16x8_splat(ca)),
            i32x4_extmul_high_i16x8(b, i16x8_splat(cb))
        )
    } else {
        (
            i32x4_extmul_low_i16x8(a, i16x8_splat(ca)),
            i32x4_extmul_low_i16x8(b, i16x8_splat(cb))
        )
    };
    i32x4_shr(i32x4_add(i32x4_add(y0, pa), pb), 14)
}

/// Eight pixels: R, G and B as `i16x8` (not yet clamped).
#[inline(always)]
fn convert8(y: v128, cb: v128, cr: v128) -> (v128, v128, v128) {
    let bias = i16x8_splat(128);
    let cb = i16x8_sub(cb, bias);
    let cr = i16x8_sub(cr, bias);
    let rnd = i32x4_splat(i32::from(YUV_RND));
    let y_lo = i32x4_add(i32x4_extmul_low_i16x8(y, i16x8_splat(Y_CF)), rnd);
    let y_hi = i32x4_add(i32x4_extmul_high_i16x8(y, i16x8_splat(Y_CF)), rnd);
    let zero = i16x8_splat(0);
    let r = i16x8_narrow_i32x4(
        channel(y_lo, cr, CR_CF, zero, 0, false),
        channel(y_hi, cr, CR_CF, zero, 0, true)
    );
    let g = i16x8_narrow_i32x4(
        channel(y_lo, cr, C_G_CR_COEF_1, cb, C_G_CB_COEF_2, false),
        channel(y_hi, cr, C_G_CR_COEF_1, cb, C_G_CB_COEF_2, true)
    );
    let b = i16x8_narrow_i32x4(
        channel(y_lo, cb, CB_CF, zero, 0, false),
        channel(y_hi, cb, CB_CF, zero, 0, true)
    );
    (r, g, b)
}

/// Sixteen pixels: R, G and B as `u8x16`, clamped to 0..=255 (the saturating narrowings
/// i32 → i16 → u8 clamp exactly as the scalar `clamp`).
#[inline(always)]
fn convert16(y: &[i16; 16], cb: &[i16; 16], cr: &[i16; 16]) -> (v128, v128, v128) {
    let (r0, g0, b0) = convert8(load_i16x8(y, 0), load_i16x8(cb, 0), load_i16x8(cr, 0));
    let (r1, g1, b1) = convert8(load_i16x8(y, 8), load_i16x8(cb, 8), load_i16x8(cr, 8));
    (
        u8x16_narrow_i16x8(r0, r1),
        u8x16_narrow_i16x8(g0, g1),
        u8x16_narrow_i16x8(b0, b1)
    )
}

/// YCbCr → RGB for 16 pixels, written as 48 bytes at `output[*pos..]`; `*pos` advances by 48
/// (the contract of `scalar::ycbcr_to_rgb_inner_16_scalar::<false>`).
pub fn ycbcr_to_rgb_wasm(
    y: &[i16; 16], cb: &[i16; 16], cr: &[i16; 16], output: &mut [u8], pos: &mut usize
) {
    let (r, g, b) = convert16(y, cb, cr);
    // Interleave: R and G pairs for pixels 0–5, 5–10 and 10–15, then B dropped in between.
    let rg0 = u8x16_shuffle::<0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 0, 0, 0, 0>(r, g);
    let rg1 = u8x16_shuffle::<5, 21, 6, 22, 7, 23, 8, 24, 9, 25, 10, 26, 0, 0, 0, 0>(r, g);
    let rg2 = u8x16_shuffle::<11, 27, 12, 28, 13, 29, 14, 30, 15, 31, 0, 0, 0, 0, 0, 0>(r, g);
    let o0 = u8x16_shuffle::<0, 1, 16, 2, 3, 17, 4, 5, 18, 6, 7, 19, 8, 9, 20, 10>(rg0, b);
    let o1 = u8x16_shuffle::<1, 21, 2, 3, 22, 4, 5, 23, 6, 7, 24, 8, 9, 25, 10, 11>(rg1, b);
    let o2 = u8x16_shuffle::<26, 0, 1, 27, 2, 3, 28, 4, 5, 29, 6, 7, 30, 8, 9, 31>(rg2, b);
    store_u8x16(output, *pos, o0);
    store_u8x16(output, *pos + 16, o1);
    store_u8x16(output, *pos + 32, o2);
    *pos += 48;
}

/// YCbCr → RGBA (alpha 255) for 16 pixels, written as 64 bytes at `output[*pos..]`; `*pos`
/// advances by 64 (the contract of `scalar::ycbcr_to_rgba_inner_16_scalar::<false>`).
pub fn ycbcr_to_rgba_wasm(
    y: &[i16; 16], cb: &[i16; 16], cr: &[i16; 16], output: &mut [u8], pos: &mut usize
) {
    let (r, g, b) = convert16(y, cb, cr);
    let a = u8x16_splat(255);
    let rg_lo = u8x16_shuffle::<0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23>(r, g);
    let rg_hi = u8x16_shuffle::<8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31>(r, g);
    let ba_lo = u8x16_shuffle::<0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23>(b, a);
    let ba_hi = u8x16_shuffle::<8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31>(b, a);
    store_u8x16(output, *pos, i16x8_shuffle::<0, 8, 1, 9, 2, 10, 3, 11>(rg_lo, ba_lo));
    store_u8x16(output, *pos + 16, i16x8_shuffle::<4, 12, 5, 13, 6, 14, 7, 15>(rg_lo, ba_lo));
    store_u8x16(output, *pos + 32, i16x8_shuffle::<0, 8, 1, 9, 2, 10, 3, 11>(rg_hi, ba_hi));
    store_u8x16(output, *pos + 48, i16x8_shuffle::<4, 12, 5, 13, 6, 14, 7, 15>(rg_hi, ba_hi));
    *pos += 64;
}
