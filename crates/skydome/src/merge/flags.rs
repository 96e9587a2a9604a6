//! The merge's clipped-pixel flags alone, from the codes: what [`merge`](super::merge) puts in
//! [`Merged::clipped`](super::Merged::clipped) and counts, without merging. The pipeline uses
//! it when it merges only the part of the photos the dome keeps (see
//! [`merge_window`](crate::pipeline)): the flags and their counts still describe the whole photo.

use super::{Code, Frame, Pixels, BLACK, CLIPPED_HIGH, CLIPPED_LOW};

/// The per-pixel flags of a merge of `frames` and their counts.
#[derive(Debug, Clone, PartialEq)]
pub struct ClippedFlags {
    /// Per pixel (row-major) [`CLIPPED_HIGH`] | [`CLIPPED_LOW`] | [`BLACK`], as
    /// [`Merged::clipped`](super::Merged::clipped).
    pub mask: Vec<u8>,
    /// Pixels flagged [`CLIPPED_HIGH`], as [`Merged::clipped_high`](super::Merged::clipped_high).
    pub high: usize,
    /// Pixels flagged [`CLIPPED_LOW`], as [`Merged::clipped_low`](super::Merged::clipped_low).
    pub low: usize,
    /// Pixels flagged [`BLACK`], as [`Merged::black_pixels`](super::Merged::black_pixels).
    pub black: usize,
}

/// The flags a merge of `frames` (sorted shortest exposure first, one size and bit depth, as
/// [`merge`](super::merge) checks) with `black_level` (8-bit code) gives every pixel: a channel
/// at or below the black level, or at full scale, in every frame flags the pixel
/// [`CLIPPED_HIGH`] when the shortest frame is at full scale there, else [`CLIPPED_LOW`]; every
/// channel so and below the black level in the shortest frame adds [`BLACK`]. Empty for no
/// frames.
pub fn clipped_flags(frames: &[Frame], black_level: u8) -> ClippedFlags {
    let empty = ClippedFlags {
        mask: Vec::new(),
        high: 0,
        low: 0,
        black: 0,
    };
    let Some(first) = frames.first() else {
        return empty;
    };
    match &first.pixels {
        Pixels::U8(_) => flags_of::<u8>(frames, first.width, black_level),
        Pixels::U16(_) => flags_of::<u16>(frames, first.width, black_level),
    }
}

fn flags_of<T: Code>(frames: &[Frame], w: usize, black_level: u8) -> ClippedFlags {
    let srcs: Vec<&[T]> = frames
        .iter()
        .filter_map(|f| T::samples(&f.pixels))
        .collect();
    let black = T::black(black_level);
    let n = srcs.iter().map(|s| s.len() / 3).min().unwrap_or(0);
    let mut mask = vec![0u8; n];
    let rows = 64 * w.max(1);
    let work = |(k, m): (usize, &mut [u8])| {
        let p0 = k * rows;
        let mut ext = vec![0u8; 3 * m.len()];
        let (s0, s1) = (3 * p0, 3 * (p0 + m.len()));
        // The merge's rule (`merge_band`): the shortest frame's flag per sample, kept where
        // every later frame is extreme too.
        for (e, &z0) in ext.iter_mut().zip(&srcs[0][s0..s1]) {
            let extreme = (z0 <= black || z0 == T::MAX) as u8;
            *e = extreme * (CLIPPED_LOW - (z0 == T::MAX) as u8);
        }
        for s in &srcs[1..] {
            for (e, &z) in ext.iter_mut().zip(&s[s0..s1]) {
                *e *= (z <= black || z == T::MAX) as u8;
            }
        }
        let (mut high, mut low, mut blk) = (0usize, 0usize, 0usize);
        for (f, e) in m.iter_mut().zip(ext.chunks_exact(3)) {
            let mut flag = e[0] | e[1] | e[2];
            high += (flag & CLIPPED_HIGH) as usize;
            low += (flag >> 1) as usize;
            if e[0] & e[1] & e[2] & CLIPPED_LOW != 0 {
                flag |= BLACK;
                blk += 1;
            }
            *f = flag;
        }
        (high, low, blk)
    };
    let add =
        |a: (usize, usize, usize), b: (usize, usize, usize)| (a.0 + b.0, a.1 + b.1, a.2 + b.2);
    #[cfg(feature = "parallel")]
    let (high, low, black) = {
        use rayon::prelude::*;
        mask.par_chunks_mut(rows)
            .enumerate()
            .map(work)
            .reduce(|| (0, 0, 0), add)
    };
    #[cfg(not(feature = "parallel"))]
    let (high, low, black) = mask
        .chunks_mut(rows)
        .enumerate()
        .map(work)
        .fold((0, 0, 0), add);
    ClippedFlags {
        mask,
        high,
        low,
        black,
    }
}
