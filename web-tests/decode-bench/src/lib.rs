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
        if high != 0 { (h >> 32) as u32 } else { h as u32 }
    })
}

/// Frees the last output.
#[no_mangle]
pub extern "C" fn release() {
    OUTPUT.set(Vec::new());
}
