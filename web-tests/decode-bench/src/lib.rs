//! One JPEG decode through zune-jpeg as `image` 0.25 calls it (RGB out, not strict, a fresh
//! zeroed output buffer, `decode_into`), exported without wasm-bindgen so that `run.mjs` can
//! load two builds (main's and a branch's) in one page and alternate them.

use std::cell::RefCell;

use zune_core::bytestream::ZCursor;
use zune_core::colorspace::ColorSpace;
use zune_core::options::DecoderOptions;

thread_local! {
    static INPUT: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
    static OUTPUT: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
}

/// A buffer of `len` bytes for the JPEG file; the caller writes the file there.
#[no_mangle]
pub extern "C" fn input_buf(len: usize) -> *mut u8 {
    INPUT.with_borrow_mut(|v| {
        *v = vec![0; len];
        v.as_mut_ptr()
    })
}

/// Decodes the input to 8-bit RGB; returns the output's length in bytes, 0 if it failed.
#[no_mangle]
pub extern "C" fn decode() -> usize {
    INPUT.with_borrow(|input| {
        let opts = DecoderOptions::default()
            .jpeg_set_out_colorspace(ColorSpace::RGB)
            .set_strict_mode(false);
        let mut d = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(&input[..]), opts);
        if d.decode_headers().is_err() {
            return 0;
        }
        let Some((w, h)) = d.dimensions() else {
            return 0;
        };
        let mut out = vec![0; w * h * 3];
        if d.decode_into(&mut out).is_err() {
            return 0;
        }
        let n = out.len();
        OUTPUT.set(out);
        n
    })
}

/// FNV-1a (64-bit) of the last output, as two 32-bit halves: `hash(1)` the high one.
#[no_mangle]
pub extern "C" fn hash(high: u32) -> u32 {
    OUTPUT.with_borrow(|out| {
        let h = out.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        });
        if high != 0 {
            (h >> 32) as u32
        } else {
            h as u32
        }
    })
}

/// Frees the last output.
#[no_mangle]
pub extern "C" fn release() {
    OUTPUT.set(Vec::new());
}

/// The vendored zune-jpeg's scalar and wasm simd128 colour conversions, compiled here from
/// their source files (they are private to the crate) to compare them on every input.
#[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
#[path = "colour.rs"]
mod color_convert;

/// Compares zune-jpeg's wasm YCbCr → RGB and → RGBA with its scalar code, 16 pixels per call:
/// every (y, cb, cr) in 0..=255, then `random` calls on xorshift `i16` triples. Returns how many
/// calls differ (0 when bit-identical). `node -e` example in run.mjs's header.
#[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
#[no_mangle]
pub extern "C" fn colour_mismatches(random: u32) -> u32 {
    use color_convert::{scalar, wasm};
    let differ = |y: &[i16; 16], cb: &[i16; 16], cr: &[i16; 16]| {
        let (mut a, mut b) = ([0u8; 48], [0u8; 48]);
        scalar::ycbcr_to_rgb_inner_16_scalar::<false>(y, cb, cr, &mut a, &mut 0);
        wasm::ycbcr_to_rgb_wasm(y, cb, cr, &mut b, &mut 0);
        let (mut c, mut d) = ([0u8; 64], [0u8; 64]);
        scalar::ycbcr_to_rgba_inner_16_scalar::<false>(y, cb, cr, &mut c, &mut 0);
        wasm::ycbcr_to_rgba_wasm(y, cb, cr, &mut d, &mut 0);
        u32::from(a != b || c != d)
    };
    let mut bad = 0;
    let (mut y, mut cb, mut cr) = ([0i16; 16], [0i16; 16], [0i16; 16]);
    for yv in 0..256 {
        for cbv in 0..256 {
            for cr0 in (0..256).step_by(16) {
                y = [yv; 16];
                cb = [cbv; 16];
                for (i, c) in cr.iter_mut().enumerate() {
                    *c = cr0 + i as i16;
                }
                bad += differ(&y, &cb, &cr);
            }
        }
    }
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s as i16
    };
    for _ in 0..random {
        for i in 0..16 {
            (y[i], cb[i], cr[i]) = (next(), next(), next());
        }
        bad += differ(&y, &cb, &cr);
    }
    bad
}
