//! Translation alignment of hand-held brackets by median threshold bitmaps (Ward 2003, the
//! method of OpenCV's `AlignMTB`).
//!
//! A frame's *median threshold bitmap* marks the pixels brighter than the frame's median grey
//! level. Whatever the exposure, roughly the same half of the scene lies above the median, so
//! the bitmaps of a bracket look alike where exposures differ by stops and can be compared by
//! counting differing bits. Pixels within [`EXCLUDE`] codes of the median flip with noise and
//! are left out (the *exclusion bitmap*). The shift of each frame against the reference (the
//! middle exposure) is found coarse to fine on an image pyramid: at every level the shift from
//! the level below, doubled, is refined by testing the nine offsets of ±1 pixel. With `L`
//! levels shifts up to `2^L − 1` pixels are found.
//!
//! Shifts are integers in pixels, `(dx, dy)` with `x` right and `y` down: the content of the
//! frame sits `(dx, dy)` away from where it sits in the reference, and [`apply_shifts`] moves
//! it back (edges are repeated where the frame has no data). Rotation is not modelled: a phone
//! lying still on its back only slides.
//!
//! Written here rather than taken from a crate: no maintained Rust crate implements MTB, and
//! OpenCV is not available to a wasm build.
//!
//! Reference: G. Ward, *Fast, Robust Image Registration for Compositing High Dynamic Range
//! Photographs from Hand-Held Exposures*, Journal of Graphics Tools 8(2), 2003.

use crate::bracket::{bin16, Frame, Pixels};

/// Grey levels (8-bit) within this distance of the median are excluded from the comparison.
pub const EXCLUDE: u8 = 4;

/// Alignment options.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AlignOptions {
    /// Largest shift searched, pixels (1..=1024); the pyramid has `⌈log2(max_shift + 1)⌉`
    /// levels. Default 64.
    pub max_shift: u32,
    /// Shifts in whole pairs of pixels only (default `false`): for frames demosaiced from one
    /// 2 × 2 colour filter array (a RAW bracket), an odd shift would move the mosaic's phase,
    /// and the merge, which tells measured photosites from interpolated ones by the first
    /// frame's phase, would take one for the other. The full-resolution level then tests the
    /// offsets 0 and ±2 instead of 0 and ±1 (the result is within 1 pixel of the best shift).
    #[serde(default)]
    pub even: bool,
}

impl Default for AlignOptions {
    fn default() -> Self {
        Self {
            max_shift: 64,
            even: false,
        }
    }
}

/// What [`align`] found.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Alignment {
    /// Index of the reference frame (the middle exposure).
    pub reference: usize,
    /// Per frame, `(dx, dy)` pixels of its content relative to the reference (0, 0 for it).
    pub shifts: Vec<(i32, i32)>,
}

impl Alignment {
    /// Largest shift in either direction, pixels.
    pub fn largest(&self) -> u32 {
        self.shifts
            .iter()
            .map(|&(x, y)| x.unsigned_abs().max(y.unsigned_abs()))
            .max()
            .unwrap_or(0)
    }
}

/// 8-bit grey of every pixel: `(54 R + 183 G + 19 B) / 256` (Rec. 709 weights).
fn grey(f: &Frame) -> Vec<u8> {
    let n = f.width * f.height;
    let px = |i: usize| -> [u32; 3] {
        match &f.pixels {
            Pixels::U8(v) => [v[3 * i] as u32, v[3 * i + 1] as u32, v[3 * i + 2] as u32],
            Pixels::U16(v) => [
                bin16(v[3 * i]) as u32,
                bin16(v[3 * i + 1]) as u32,
                bin16(v[3 * i + 2]) as u32,
            ],
        }
    };
    (0..n)
        .map(|i| {
            let [r, g, b] = px(i);
            ((54 * r + 183 * g + 19 * b) >> 8) as u8
        })
        .collect()
}

/// Halves an image by 2 × 2 means (odd last row/column dropped).
fn half(img: &[u8], w: usize, h: usize) -> (Vec<u8>, usize, usize) {
    let (hw, hh) = (w / 2, h / 2);
    let mut out = Vec::with_capacity(hw * hh);
    for y in 0..hh {
        for x in 0..hw {
            let s = img[2 * y * w + 2 * x] as u32
                + img[2 * y * w + 2 * x + 1] as u32
                + img[(2 * y + 1) * w + 2 * x] as u32
                + img[(2 * y + 1) * w + 2 * x + 1] as u32;
            out.push(((s + 2) / 4) as u8);
        }
    }
    (out, hw, hh)
}

/// The grey level below which a fraction `q` of the pixels lies.
fn quantile(img: &[u8], q: f64) -> u8 {
    let mut hist = [0usize; 256];
    for &v in img {
        hist[v as usize] += 1;
    }
    let mut acc = 0usize;
    for (v, &n) in hist.iter().enumerate() {
        acc += n;
        if acc as f64 >= q * img.len() as f64 {
            return v as u8;
        }
    }
    255
}

/// Threshold and exclusion bitmaps: bit 0 = above the `q`-quantile, bit 1 = usable.
fn bitmaps(img: &[u8], q: f64) -> Vec<u8> {
    let med = quantile(img, q);
    img.iter()
        .map(|&v| (v > med) as u8 | (((v.abs_diff(med)) > EXCLUDE) as u8) << 1)
        .collect()
}

/// The fraction of differing threshold bits among the pixels usable in both when `b` is
/// shifted by `(dx, dy)` against `a`. A fraction, not a count: a count falls as the overlap
/// shrinks, which would favour large shifts.
fn mismatch(a: &[u8], b: &[u8], w: usize, h: usize, dx: i32, dy: i32) -> f64 {
    let (mut err, mut both) = (0u64, 0u64);
    let (x0, x1) = (dx.max(0) as usize, (w as i32 + dx.min(0)).max(0) as usize);
    for y in 0..h {
        let yb = y as i32 - dy;
        if yb < 0 || yb >= h as i32 {
            continue;
        }
        let ra = &a[y * w..(y + 1) * w];
        let rb = &b[yb as usize * w..(yb as usize + 1) * w];
        if x1 <= x0 {
            continue;
        }
        let sb = (x0 as i32 - dx) as usize;
        for (&pa, &pb) in ra[x0..x1].iter().zip(&rb[sb..sb + (x1 - x0)]) {
            // Both usable (bit 1) and threshold bits differ (bit 0).
            let usable = ((pa & pb) >> 1) & 1;
            err += (usable & (pa ^ pb)) as u64;
            both += usable as u64;
        }
    }
    if both == 0 {
        1.0
    } else {
        err as f64 / both as f64
    }
}

/// Estimates each frame's translation against the middle exposure. Frames must share one size
/// (they do in a [`crate::bracket::Bracket`]); frames of another size get shift (0, 0).
pub fn align(frames: &[Frame], opts: &AlignOptions) -> Alignment {
    let reference = frames.len() / 2;
    let mut shifts = vec![(0i32, 0i32); frames.len()];
    let Some(rf) = frames.get(reference) else {
        return Alignment { reference, shifts };
    };
    let levels = (32 - opts.max_shift.clamp(1, 1024).leading_zeros()) as usize;
    let pyramid = |f: &Frame, q: f64| {
        let mut out = vec![(grey(f), f.width, f.height)];
        for _ in 1..levels {
            let (img, w, h) = match out.last() {
                Some(l) => (&l.0, l.1, l.2),
                None => break,
            };
            // Levels under ≈ 32 pixels hold too little structure to choose between shifts.
            if w < 64 || h < 64 {
                break;
            }
            let next = half(img, w, h);
            out.push(next);
        }
        out.into_iter()
            .map(|(g, w, h)| (bitmaps(&g, q), w, h))
            .collect::<Vec<_>>()
    };
    let gr = grey(rf);
    for (j, f) in frames.iter().enumerate() {
        if j == reference || (f.width, f.height) != (rf.width, rf.height) {
            continue;
        }
        // The median, unless it is black or clipped in either frame (a long exposure of a sky
        // is mostly white): then the nearest quantile that splits both frames inside their
        // range, as Ward suggests for such exposures.
        let gf = grey(f);
        let ok = |v: u8| (EXCLUDE + 4..=251 - EXCLUDE).contains(&v);
        let q = [0.5, 0.4, 0.6, 0.3, 0.7, 0.2, 0.8, 0.1, 0.9]
            .into_iter()
            .find(|&q| ok(quantile(&gr, q)) && ok(quantile(&gf, q)))
            .unwrap_or(0.5);
        let pr = pyramid(rf, q);
        let pf = pyramid(f, q);
        let (mut sx, mut sy) = (0i32, 0i32);
        for (level, ((a, w, h), (b, _, _))) in pr.iter().zip(&pf).enumerate().rev() {
            sx *= 2;
            sy *= 2;
            // Coarser levels' shifts are doubled, so they are even at full resolution anyway.
            let step = if opts.even && level == 0 { 2 } else { 1 };
            let mut best = (f64::INFINITY, sx, sy);
            for dy in [-step, 0, step] {
                for dx in [-step, 0, step] {
                    let e = mismatch(a, b, *w, *h, sx + dx, sy + dy);
                    // Ties keep the smaller shift (visited first from the centre outwards
                    // would be fairer; the ±1 grid is small enough that any tie is noise).
                    if e < best.0 || (e == best.0 && dx == 0 && dy == 0) {
                        best = (e, sx + dx, sy + dy);
                    }
                }
            }
            (sx, sy) = (best.1, best.2);
        }
        // `mismatch` shifts the frame's bitmap by (sx, sy) onto the reference; the frame's
        // content therefore sits at −(sx, sy).
        shifts[j] = (-sx, -sy);
    }
    Alignment { reference, shifts }
}

/// Moves each frame's content by `−shift` so it lines up with the reference; pixels with no
/// data repeat the nearest edge pixel.
pub fn apply_shifts(frames: &[Frame], a: &Alignment) -> Vec<Frame> {
    frames
        .iter()
        .zip(a.shifts.iter().chain(std::iter::repeat(&(0, 0))))
        .map(|(f, &(dx, dy))| {
            if (dx, dy) == (0, 0) {
                return f.clone();
            }
            fn shift<T: Copy>(v: &[T], w: usize, h: usize, dx: i32, dy: i32) -> Vec<T> {
                let mut out = Vec::with_capacity(v.len());
                for y in 0..h {
                    let ys = (y as i32 + dy).clamp(0, h as i32 - 1) as usize;
                    for x in 0..w {
                        let xs = (x as i32 + dx).clamp(0, w as i32 - 1) as usize;
                        let i = 3 * (ys * w + xs);
                        out.extend_from_slice(&v[i..i + 3]);
                    }
                }
                out
            }
            let pixels = match &f.pixels {
                Pixels::U8(v) => Pixels::U8(shift(v, f.width, f.height, dx, dy)),
                Pixels::U16(v) => Pixels::U16(shift(v, f.width, f.height, dx, dy)),
            };
            Frame {
                name: f.name.clone(),
                width: f.width,
                height: f.height,
                pixels,
                exposure: f.exposure,
            }
        })
        .collect()
}

/// Aligns a bracket's frames in place: finds the shifts ([`align`]) and moves each frame's
/// content onto the reference ([`apply_shifts`]). The one alignment step of skydome: what
/// [`crate::pipeline::run`] does with `align` set (`merge --align`) and what `calibrate --align`
/// does before sampling, so a hand-held bracket calibrates on the pixels it will be merged on.
pub fn align_bracket(frames: &mut Vec<Frame>, opts: &AlignOptions) -> Alignment {
    let a = align(frames, opts);
    if a.shifts.iter().any(|&s| s != (0, 0)) {
        *frames = apply_shifts(frames, &a);
    }
    a
}
