//! Branch-free `log₂` and `2ˣ` in `f32` for per-pixel loops (the merge, the tone map's
//! statistics and its sRGB encoding).
//!
//! Hand-written because the standard `log2`/`exp2` are opaque library calls per sample, which
//! stop a loop from vectorising; a small polynomial inlines and vectorises (SSE2 on x86-64,
//! SIMD128 on wasm when enabled), and no crate offers one without a SIMD framework.

/// `a.max(b)` for loops that must vectorise on wasm32 too: there `f32::max`'s NaN rule has no
/// instruction and becomes a call to `fmaxf` per sample, which stops a loop from vectorising
/// (the browser's tone map took 1.4× as long with it), so on wasm32 it is a compare and a select
/// (`f32x4.pmax` with SIMD128): `b` when `a` is NaN, as `f32::max`, but NaN when only `b` is,
/// so callers pass a possible NaN as `a`. Elsewhere it is `f32::max`, which measured faster on
/// x86-64 than the select (43 against 50 ms for the 6 MP tone map). Of two zeros either may come
/// back. (`f32::clamp` is compares and selects on every target already.)
#[inline(always)]
pub(crate) fn max(a: f32, b: f32) -> f32 {
    if cfg!(target_arch = "wasm32") {
        if a > b {
            a
        } else {
            b
        }
    } else {
        a.max(b)
    }
}

/// `a.min(b)` the way [`max`] is `a.max(b)`: on wasm32 a compare and a select (`b` when `a` is
/// NaN, NaN when only `b` is, so callers pass a possible NaN as `a`) instead of a call to
/// `fminf` per sample; elsewhere `f32::min`. Of two zeros either may come back.
#[inline(always)]
pub(crate) fn min(a: f32, b: f32) -> f32 {
    if cfg!(target_arch = "wasm32") {
        if a < b {
            a
        } else {
            b
        }
    } else {
        a.min(b)
    }
}

/// `log₂ x` for positive, finite, **normal** `x`: the exponent from the bits and `log₂ m` of the
/// mantissa `m ∈ [1, 2)` by a degree-6 least-squares polynomial; absolute error below 3·10⁻⁶
/// plus the `f32` rounding of the sum (half an ulp of `|log₂ x|`, up to 4·10⁻⁶ at the ends).
/// Zero, negative, subnormal or non-finite `x` give garbage the caller must not use.
#[inline(always)]
pub(crate) fn log2(x: f32) -> f32 {
    let bits = x.to_bits();
    let e = ((bits >> 23) & 0xff) as i32 - 127;
    let t = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000) - 1.0;
    const C: [f32; 6] = [
        1.442_534_8,
        -0.718_033_6,
        0.457_158_1,
        -0.277_341_65,
        0.121_472_95,
        -0.025_792_345,
    ];
    let p = C[5];
    let p = p * t + C[4];
    let p = p * t + C[3];
    let p = p * t + C[2];
    let p = p * t + C[1];
    let p = p * t + C[0];
    e as f32 + p * t
}

/// `2ˣ`: `x` is clamped to ±126, split by round-to-nearest into `k + f` with `|f| ≤ ½`, and
/// `2ᶠ` is a degree-5 polynomial fitted for minimum relative error on `[−½, ½]`. Relative error
/// below 3·10⁻⁷; NaN stays NaN.
#[inline(always)]
pub fn exp2(x: f32) -> f32 {
    let x = x.clamp(-EXP2_LIMIT, EXP2_LIMIT);
    let t = x + EXP2_MAGIC;
    let k = t.to_bits() as i32 - EXP2_MAGIC.to_bits() as i32;
    let f = x - (t - EXP2_MAGIC);
    let [c0, c1, c2, c3, c4, c5] = EXP2_C;
    let p = c0 + f * (c1 + f * (c2 + f * (c3 + f * (c4 + f * c5))));
    p * f32::from_bits(((k + 127) as u32) << 23)
}

/// [`exp2`]'s clamp of its argument.
pub(crate) const EXP2_LIMIT: f32 = 126.0;
/// [`exp2`]'s rounding constant, 1.5 · 2²³: adding it rounds to an integer in the low bits.
pub(crate) const EXP2_MAGIC: f32 = 12_582_912.0;
/// [`exp2`]'s polynomial `2ᶠ ≈ Σ c_i fⁱ` on `[−½, ½]` (the merge's vector kernel evaluates the
/// same operations in the same order, so both give the same bits).
pub(crate) const EXP2_C: [f32; 6] = [
    1.000_000_1,
    0.693_146_94,
    0.240_221_2,
    0.055_507_13,
    0.009_675_542,
    0.001_327_647_2,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log2_is_within_3e6_of_std_log2_over_the_normal_range() {
        let mut worst = 0f64;
        let mut x = f32::MIN_POSITIVE;
        while x < 1e38 {
            let exact = f64::from(x).log2();
            // The polynomial's error, beyond half an ulp of the f32 result.
            let ulp = f64::from(f32::EPSILON) * exact.abs();
            worst = worst.max((f64::from(log2(x)) - exact).abs() - 0.5 * ulp);
            x *= 1.000_37;
        }
        assert!(worst < 3e-6, "{worst}");
        assert_eq!(log2(1.0), 0.0);
        assert_eq!(log2(0.25), -2.0);
    }

    #[test]
    fn exp2_is_within_3e7_relative_of_std_exp2() {
        let mut worst = 0f64;
        let mut x = -120.0f32;
        while x < 120.0 {
            let a = f64::from(exp2(x));
            let b = f64::from(x).exp2();
            worst = worst.max(((a - b) / b).abs());
            x += 0.00731;
        }
        assert!(worst < 3e-7, "worst relative error {worst}");
    }

    #[test]
    fn exp2_saturates_instead_of_wrapping() {
        assert!(exp2(1000.0).is_finite() && exp2(1000.0) > 1e37);
        assert!(exp2(-1000.0) >= 0.0 && exp2(-1000.0) < 1e-37);
        assert!(exp2(f32::NAN).is_nan());
    }
}
