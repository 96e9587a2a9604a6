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

use crate::color_convert::scalar::{
    CB_CF, CR_CF, C_G_CB_COEF_2, C_G_CR_COEF_1, YUV_PREC, YUV_RND, Y_CF
};

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

/// Eight `i16` constants, `a` in the even lanes and `b` in the odd ones: the second operand of
/// `i32x4_dot_i16x8` on pairs interleaved as `(a-operand, b-operand)`.
#[inline(always)]
fn pair(a: i16, b: i16) -> v128 {
    i16x8(a, b, a, b, a, b, a, b)
}

/// The low (`HIGH = false`) or high four `i16` lanes of `a` and `b`, interleaved `a0 b0 a1 b1 …`.
#[inline(always)]
fn zip<const HIGH: bool>(a: v128, b: v128) -> v128 {
    match HIGH {
        false => i16x8_shuffle::<0, 8, 1, 9, 2, 10, 3, 11>(a, b),
        true => i16x8_shuffle::<4, 12, 5, 13, 6, 14, 7, 15>(a, b)
    }
}

/// Four pixels (the low or high half of eight) as `i32x4`: R, G, B before the clamp.
///
/// Each channel is the scalar code's sum of 32-bit products plus the rounding constant,
/// shifted right by 14. The products come in pairs from `i32x4_dot_i16x8` (x86-64's `pmaddwd`,
/// one instruction where an `extmul` takes three): `y·Y_CF + cr·CR_CF` for R,
/// `cr·C_G_CR_COEF_1 + cb·C_G_CB_COEF_2` (plus `y·Y_CF`) for G, `y·Y_CF + cb·CB_CF` for B. A dot
/// product of two `i16` pairs is exact in `i32` unless both pairs are -32768·-32768 (no
/// coefficient is -32768), and the sums stay far inside `i32` (|coefficients| ≤ 45 416, operands
/// ≤ 32 768), so every channel equals the scalar value bit for bit.
#[inline(always)]
fn convert4<const HIGH: bool>(y: v128, cb: v128, cr: v128) -> (v128, v128, v128) {
    // `y · Y_CF` for G as a shift: Y_CF is 1 << YUV_PREC.
    const _: () = assert!(Y_CF as i32 == 1 << YUV_PREC);
    let rnd = i32x4_splat(i32::from(YUV_RND));
    let y32 = match HIGH {
        false => i32x4_extend_low_i16x8(y),
        true => i32x4_extend_high_i16x8(y)
    };
    let y0 = i32x4_add(i32x4_shl(y32, YUV_PREC as u32), rnd);
    let r = i32x4_dot_i16x8(zip::<HIGH>(y, cr), pair(Y_CF, CR_CF));
    let g = i32x4_dot_i16x8(zip::<HIGH>(cr, cb), pair(C_G_CR_COEF_1, C_G_CB_COEF_2));
    let b = i32x4_dot_i16x8(zip::<HIGH>(y, cb), pair(Y_CF, CB_CF));
    let shift = |v: v128| i32x4_shr(v, YUV_PREC as u32);
    (
        shift(i32x4_add(r, rnd)),
        shift(i32x4_add(g, y0)),
        shift(i32x4_add(b, rnd))
    )
}

/// Eight pixels: R, G and B as `i16x8` (not yet clamped).
#[inline(always)]
fn convert8(y: v128, cb: v128, cr: v128) -> (v128, v128, v128) {
    let bias = i16x8_splat(128);
    let cb = i16x8_sub(cb, bias);
    let cr = i16x8_sub(cr, bias);
    let (r0, g0, b0) = convert4::<false>(y, cb, cr);
    let (r1, g1, b1) = convert4::<true>(y, cb, cr);
    (
        i16x8_narrow_i32x4(r0, r1),
        i16x8_narrow_i32x4(g0, g1),
        i16x8_narrow_i32x4(b0, b1)
    )
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
#[inline(always)]
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
#[inline(always)]
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

/// YCbCr → RGB (`RGBA = false`, 48 bytes per 16 pixels) or RGBA (64 bytes) for as many whole
/// groups of 16 pixels as `y`, `cb`, `cr` and `output` all hold: what `worker.rs`'s row loop
/// does with one `ycbcr_to_rgb(a)_wasm` call per 16 pixels, in one call, so V8 keeps the
/// constants in registers and makes no indirect call per group (the per-call form was a sixth
/// of a 12 MP 4:4:4 decode in Chromium's profile).
pub fn ycbcr_to_rgb_row_wasm<const RGBA: bool>(
    y: &[i16], cb: &[i16], cr: &[i16], output: &mut [u8]
) {
    let bytes = if RGBA { 64 } else { 48 };
    for (((y, cb), cr), out) in y
        .chunks_exact(16)
        .zip(cb.chunks_exact(16))
        .zip(cr.chunks_exact(16))
        .zip(output.chunks_exact_mut(bytes))
    {
        let (y, cb, cr) = (y.try_into().unwrap(), cb.try_into().unwrap(), cr.try_into().unwrap());
        if RGBA {
            ycbcr_to_rgba_wasm(y, cb, cr, out, &mut 0);
        } else {
            ycbcr_to_rgb_wasm(y, cb, cr, out, &mut 0);
        }
    }
}
