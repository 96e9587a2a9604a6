//! The hat merge: per-frame look-up tables of `(w, w · log2 E_j)`, summed a few frames at a
//! time over bands of rows, then the clipped-pixel flags and the confidence of each row.

use super::refine::{refine_row, Scratch};
use super::{code_tables, fast_exp2, Code, Frame, Refinement, Weighting};
use super::{BLACK, CLIPPED_HIGH, CLIPPED_LOW, RELEASE_BANDS, ROWS_PER_BAND};

/// Peak of the 8-bit hat: the full weight.
pub(super) const W_MAX: f32 = 127.0;
/// Floor weight of the shortest frame: keeps `Σ w > 0` without moving any real result.
pub(super) const W_FLOOR: f32 = 1e-6;

#[inline]
pub(super) fn hat_f(z: f32) -> f32 {
    z.min(255.0 - z).max(0.0)
}

/// Weight of code `z` (continuous 0..=255) in frame `j` of `p` for the given weighting.
pub(super) fn weight(z: f32, j: usize, p: usize, weighting: Weighting) -> f32 {
    match weighting {
        Weighting::None => 1.0,
        // Without a noise model (never reached from `merge_into`, which builds one) the hat.
        Weighting::Hat | Weighting::Noise => {
            let mut w = hat_f(z);
            if j == 0 && z >= 127.5 {
                w = W_MAX;
            }
            if j + 1 == p && z <= 127.5 {
                w = W_MAX;
            }
            if j == 0 {
                w = w.max(W_FLOOR);
            }
            w
        }
    }
}

/// The look-up tables of every frame and channel: per code, `(w, w · log2 E_j)` with
/// `log2 E_j = (g − ln Δt_j) · log2 e`. Working in base 2 lets the merge end with `2^x`, the
/// cheapest exponential. One flat allocation, frame-major then channel, so a group of frames'
/// tables is one fixed-size array (one base register in the inner loop, no bounds checks).
pub(super) struct Tables<const N: usize> {
    flat: Vec<[f32; 2]>,
}

impl<const N: usize> Tables<N> {
    /// `g(c, code)` gives `g` (natural log) for a code of an `N`-level input and
    /// `weight(j, c, z)` the weight of frame `j`, channel `c` at the continuous 8-bit code `z`;
    /// codes map to the 8-bit scale as `code · 255 / (N − 1)`.
    pub(super) fn new(
        lt: &[f64],
        weight: impl Fn(usize, usize, f32) -> f32,
        g: impl Fn(usize, usize) -> f64,
    ) -> Self {
        let scale = 255.0 / (N - 1) as f32;
        let flat = code_tables::<N>(lt, g, |j, c, v, vote| {
            let w = weight(j, c, v as f32 * scale);
            [w, w * vote]
        });
        Self { flat }
    }

    /// Frame `j`'s entry `[w, w · log2 E_j]` for channel `c` and code `z`.
    pub(super) fn entry(&self, j: usize, c: usize, z: usize) -> [f32; 2] {
        self.flat[(j * 3 + c) * N + z]
    }

    /// The tables of frames `j0 .. j0 + G`, per channel.
    #[inline(always)]
    fn group<const G: usize>(&self, j0: usize) -> &[[[[f32; 2]; N]; 3]; G] {
        let (channels, _) = self.flat.as_chunks::<N>();
        let (frames, _) = channels.as_chunks::<3>();
        match frames[j0..j0 + G].try_into() {
            Ok(t) => t,
            Err(_) => unreachable!("a slice of G frames"),
        }
    }
}

/// One band of work: offset of its first sample, its output, confidence and mask slices.
type Band<'a> = (usize, &'a mut [f32], &'a mut [f32], &'a mut [u8]);

/// Merges all bands (in parallel with the `parallel` feature); returns the clipped-high,
/// clipped-low and black pixel counts. `conf` and `clip` are empty when not asked for; a code
/// at or below `black` counts as black. With `refine` (the noise-aware merge) each row of the
/// hat's estimate is refined as soon as it is merged.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_bands<T: Code, const N: usize>(
    srcs: &[&[T]],
    luts: &Tables<N>,
    refine: Option<&Refinement<N>>,
    w: usize,
    black: T,
    out: &mut [f32],
    conf: &mut [f32],
    clip: &mut [u8],
) -> (usize, usize, usize) {
    let band = ROWS_PER_BAND * 3 * w;
    let pband = ROWS_PER_BAND * w;
    let bands = out.len().div_ceil(band.max(1));
    let mut conf_chunks = conf.chunks_mut(pband.max(1));
    let mut clip_chunks = clip.chunks_mut(pband.max(1));
    let jobs: Vec<Band<'_>> = out
        .chunks_mut(band.max(1))
        .enumerate()
        .map(|(k, o)| {
            (
                k * band,
                o,
                conf_chunks.next().unwrap_or_default(),
                clip_chunks.next().unwrap_or_default(),
            )
        })
        .collect();
    debug_assert_eq!(jobs.len(), bands);
    let work = |(off, o, c, m): Band<'_>| merge_band(srcs, luts, refine, w, black, off, o, c, m);
    let add =
        |a: (usize, usize, usize), b: (usize, usize, usize)| (a.0 + b.0, a.1 + b.1, a.2 + b.2);
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        jobs.into_par_iter().map(work).reduce(|| (0, 0, 0), add)
    }
    #[cfg(not(feature = "parallel"))]
    jobs.into_iter().map(work).fold((0, 0, 0), add)
}

/// [`run_bands`] over [`RELEASE_BANDS`] bands of rows from the bottom up, giving each band's
/// frame rows back once it is merged (see [`merge_releasing`](super::merge_releasing)).
#[allow(clippy::too_many_arguments)]
pub(super) fn run_releasing<T: Code, const N: usize>(
    frames: &mut [Frame],
    luts: &Tables<N>,
    refine: Option<&Refinement<N>>,
    w: usize,
    black: T,
    out: &mut [f32],
    conf: &mut [f32],
    clip: &mut [u8],
) -> (usize, usize, usize) {
    let h = out.len() / (3 * w).max(1);
    let rows = h.div_ceil(RELEASE_BANDS).max(1);
    let mut total = (0, 0, 0);
    for b in (0..h.div_ceil(rows)).rev() {
        let (r0, r1) = (b * rows, ((b + 1) * rows).min(h));
        let (s0, s1) = (3 * r0 * w, 3 * r1 * w);
        let srcs: Vec<&[T]> = frames
            .iter()
            .filter_map(|f| T::samples(&f.pixels))
            .map(|v| &v[s0..s1])
            .collect();
        let (cr, mr) = (
            band_of(conf.len(), r0 * w, r1 * w),
            band_of(clip.len(), r0 * w, r1 * w),
        );
        let c = run_bands(
            &srcs,
            luts,
            refine,
            w,
            black,
            &mut out[s0..s1],
            &mut conf[cr],
            &mut clip[mr],
        );
        total = (total.0 + c.0, total.1 + c.1, total.2 + c.2);
        for f in frames.iter_mut() {
            f.pixels.release_from(s0);
        }
    }
    total
}

/// The range `a..b` of an optional per-pixel output (`0..0` when it was not asked for).
fn band_of(len: usize, a: usize, b: usize) -> std::ops::Range<usize> {
    if len == 0 {
        0..0
    } else {
        a..b
    }
}

/// How a group of frames contributes to a row: the only group writes the mean
/// (`num ← Σ w · log2 E_j / Σ w`); with several groups the first writes the sums to `num` and
/// `den`, later ones add to them and [`finish_row`] divides.
const ONLY: u8 = 0;
const FIRST: u8 = 1;
const LATER: u8 = 2;

/// Adds the votes of `G` frames (`srcs`, one row each, and their tables per channel) to one
/// row per `MODE`: the mean itself for the only group, else the sums `num` (`Σ w · log2 E_j`)
/// and `den` (`Σ w`). The frames are taken a few at a time so each sample's sums stay in
/// registers; the tables are fixed-size so look-ups need no bounds checks; samples go in
/// blocks of four pixels so the division vectorises.
#[inline(always)]
fn accumulate<T: Code, const N: usize, const G: usize, const MODE: u8>(
    srcs: [&[T]; G],
    luts: &[[[[f32; 2]; N]; 3]; G],
    num: &mut [f32],
    den: &mut [f32],
) {
    // Blocks of four pixels, so the compiler can divide four samples at once.
    const B: usize = 12;
    let n = num.len();
    let (nb, ntail) = num.as_chunks_mut::<B>();
    let blocks = nb.len();
    // `den` is unused (and may be empty) for the only group.
    let den = &mut den[..if MODE == ONLY { 0 } else { n }];
    let (db, dtail) = den.as_chunks_mut::<B>();
    let db = &mut db[..if MODE == ONLY { 0 } else { blocks }];
    let sb: [&[[T; B]]; G] = srcs.map(|s| &s[..n].as_chunks::<B>().0[..blocks]);
    for i in 0..blocks {
        let (mut nv, mut dv) = ([0f32; B], [0f32; B]);
        for k in 0..B {
            let c = k % 3;
            [dv[k], nv[k]] = luts[0][c][sb[0][i][k].index()];
            for g in 1..G {
                let e = luts[g][c][sb[g][i][k].index()];
                dv[k] += e[0];
                nv[k] += e[1];
            }
        }
        match MODE {
            ONLY => {
                for k in 0..B {
                    nb[i][k] = nv[k] / dv[k];
                }
            }
            FIRST => {
                nb[i] = nv;
                db[i] = dv;
            }
            _ => {
                for k in 0..B {
                    nb[i][k] += nv[k];
                    db[i][k] += dv[k];
                }
            }
        }
    }
    // The last few pixels of the row.
    let t0 = blocks * B;
    for (k, o) in ntail.iter_mut().enumerate() {
        let c = k % 3;
        let [mut d, mut v] = luts[0][c][srcs[0][t0 + k].index()];
        for g in 1..G {
            let e = luts[g][c][srcs[g][t0 + k].index()];
            d += e[0];
            v += e[1];
        }
        match MODE {
            ONLY => *o = v / d,
            FIRST => {
                *o = v;
                dtail[k] = d;
            }
            _ => {
                *o += v;
                dtail[k] += d;
            }
        }
    }
}

/// `num ← 2^(num / den)`: the log2 radiance's weighted mean, exponentiated; with an empty
/// `den` `num` already holds the mean.
#[inline(always)]
fn finish_row(num: &mut [f32], den: &[f32]) {
    if den.is_empty() {
        for o in num.iter_mut() {
            *o = fast_exp2(*o);
        }
    } else {
        for (o, &d) in num.iter_mut().zip(den) {
            *o = fast_exp2(*o / d);
        }
    }
}

/// Dispatches the group of frames `j0 .. j0 + srcs.len()` (one to three) to [`accumulate`].
#[inline(always)]
fn accumulate_group<T: Code, const N: usize, const MODE: u8>(
    srcs: &[&[T]],
    luts: &Tables<N>,
    j0: usize,
    num: &mut [f32],
    den: &mut [f32],
) {
    match *srcs {
        [a] => accumulate::<T, N, 1, MODE>([a], luts.group(j0), num, den),
        [a, b] => accumulate::<T, N, 2, MODE>([a, b], luts.group(j0), num, den),
        [a, b, c] => accumulate::<T, N, 3, MODE>([a, b, c], luts.group(j0), num, den),
        _ => unreachable!("groups hold one to three frames"),
    }
}

#[allow(clippy::too_many_arguments)]
fn merge_band<T: Code, const N: usize>(
    srcs: &[&[T]],
    luts: &Tables<N>,
    refine: Option<&Refinement<N>>,
    w: usize,
    black: T,
    off: usize,
    out: &mut [f32],
    conf: &mut [f32],
    clip: &mut [u8],
) -> (usize, usize, usize) {
    const GROUP: usize = 3;
    let row = 3 * w;
    let mut den = vec![0f32; if srcs.len() > GROUP { row } else { 0 }];
    let mut hs = vec![0u32; if conf.is_empty() { 0 } else { row }];
    let mut ext = vec![0u8; row];
    let mut rows: Vec<&[T]> = Vec::with_capacity(srcs.len());
    let mut tails: Vec<&[T]> = Vec::with_capacity(srcs.len());
    let mut scratch = Scratch::default();
    let (mut high, mut low, mut blk) = (0usize, 0usize, 0usize);
    for (r, orow) in out.chunks_mut(row).enumerate() {
        let start = off + r * row;
        rows.clear();
        rows.extend(srcs.iter().map(|s| &s[start..start + row]));
        // The noise-aware merge's vector kernel takes what it can of the row (whole steps of
        // eight pixels), the scalar passes below the rest, with the same bits.
        let done = refine.map_or(0, |r| T::fused_row(&rows, r, orow));
        tails.clear();
        tails.extend(rows.iter().map(|s| &s[done..]));
        let dn = done.min(den.len());
        let (orest, drest) = (&mut orow[done..], &mut den[dn..]);
        if tails.len() <= GROUP {
            accumulate_group::<T, N, ONLY>(&tails, luts, 0, orest, &mut []);
        } else {
            for (k, fs) in tails.chunks(GROUP).enumerate() {
                if k == 0 {
                    accumulate_group::<T, N, FIRST>(fs, luts, 0, orest, drest);
                } else {
                    accumulate_group::<T, N, LATER>(fs, luts, k * GROUP, orest, drest);
                }
            }
        }
        match refine {
            // The noise-aware merge refines the hat's `log2 E₀` while the row is in cache.
            Some(r) => {
                if !drest.is_empty() {
                    for (o, &d) in orest.iter_mut().zip(drest.iter()) {
                        *o /= d;
                    }
                }
                refine_row(&tails, &r.scalar, &mut scratch, orest);
            }
            None => finish_row(orest, drest),
        }

        // Clipped pixels: some channel is black or full scale in every frame. Branch-free byte
        // passes over the row that vectorise: `ext` gets each sample's flag (CLIPPED_HIGH when
        // the shortest frame is saturated, else CLIPPED_LOW), then the flags are ORed per
        // pixel where there are any (fish-eye frames have black corners in most rows).
        for (e, &z0) in ext.iter_mut().zip(rows[0].iter()) {
            let extreme = (z0 <= black || z0 == T::MAX) as u8;
            *e = extreme * (CLIPPED_LOW - (z0 == T::MAX) as u8);
        }
        for s in &rows[1..] {
            for (e, &z) in ext.iter_mut().zip(s.iter()) {
                *e *= (z <= black || z == T::MAX) as u8;
            }
        }
        let prow = r * w;
        let mask = if clip.is_empty() {
            None
        } else {
            Some(&mut clip[prow..prow + w])
        };
        let (h, l, b) = pixel_flags(&ext, mask, orow);
        high += h;
        low += l;
        blk += b;

        if !conf.is_empty() {
            // Integer hat sums (`min(v, max − v)`, exact and vectorisable), then per pixel the
            // least-supported channel as a fraction of the peak weight.
            hs.fill(0);
            for s in &rows {
                for (h, &v) in hs.iter_mut().zip(s.iter()) {
                    *h += v.hat_units();
                }
            }
            for (c, hh) in conf[prow..prow + w].iter_mut().zip(hs.chunks_exact(3)) {
                *c = hh[0].min(hh[1]).min(hh[2]).min(T::HAT_PEAK) as f32 / T::HAT_PEAK as f32;
            }
        }
    }
    (high, low, blk)
}

/// ORs a row's per-sample clip flags (`ext`, 3 per pixel) per pixel into `mask` (when given),
/// and makes pixels black in every channel neutral in `out` (see [`BLACK`]); returns the number
/// of pixels flagged high, low and black. Runs of 16 pixels without a flag are skipped with one
/// vectorised test.
fn pixel_flags(ext: &[u8], mut mask: Option<&mut [u8]>, out: &mut [f32]) -> (usize, usize, usize) {
    const RUN: usize = 16;
    let (mut high, mut low, mut blk) = (0u32, 0u32, 0u32);
    for (k, run) in ext.chunks(3 * RUN).enumerate() {
        if run.iter().fold(0u8, |a, &e| a | e) == 0 {
            if let Some(m) = mask.as_deref_mut() {
                let x0 = k * RUN;
                m[x0..x0 + run.len() / 3].fill(0);
            }
            continue;
        }
        for (x, e) in run.chunks_exact(3).enumerate() {
            let mut flag = e[0] | e[1] | e[2];
            high += (flag & CLIPPED_HIGH) as u32;
            low += (flag >> 1) as u32;
            if e[0] & e[1] & e[2] & CLIPPED_LOW != 0 {
                let o = &mut out[3 * (k * RUN + x)..3 * (k * RUN + x) + 3];
                let v = o[0].min(o[1]).min(o[2]);
                o.fill(v);
                flag |= BLACK;
                blk += 1;
            }
            if let Some(m) = mask.as_deref_mut() {
                m[k * RUN + x] = flag;
            }
        }
    }
    (high as usize, low as usize, blk as usize)
}
