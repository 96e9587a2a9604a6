//! Luminance and per-channel statistics of a radiance map: one pass, no copy or sort of the
//! image, parallel over row bands when the `parallel` feature is on.
//!
//! Percentiles come from a 1/32-stop histogram of log₂ luminance (4096 bins over 2⁻⁶⁴ … 2⁶⁴),
//! the log-average from the mean of log₂ luminance. Both use a polynomial log₂ (error below
//! 3·10⁻⁶ stops, see [`fast_log2`]) instead of the C library's `log2f`, which is a call per
//! pixel the compiler cannot vectorise or inline.

// `fastmath`'s `min` and `max`: no `fminf`/`fmaxf` call per pixel on wasm32 (the same values:
// the first argument is the one that may be NaN, and a zero's sign changes no result here).
use crate::fastmath::{max, min};
use crate::image::{luminance, Circle, HdrImage, RgbImage};

#[cfg(feature = "parallel")]
use rayon::prelude::*;

use super::TonemapError;

/// Histogram range of log₂ luminance: [-64, 64) stops at 1/32 stop per bin.
const HIST_MIN_LOG2: f64 = -64.0;
const HIST_BINS_PER_STOP: f64 = 32.0;
const HIST_BINS: usize = 128 * 32;

/// Weight of a pixel that counts fully in weighted statistics (see [`Weights`]).
pub(crate) const FULL_WEIGHT: u32 = 16;

/// Luminance statistics over the unmasked pixels with positive, finite luminance.
///
/// Luminance is Rec. 709 (`0.2126 R + 0.7152 G + 0.0722 B`) of linear radiance. NaN and negative
/// channels count as zero; a pixel with a `+∞` channel counts as brighter than any other (top
/// histogram bin, left out of the log-average).
#[derive(Debug, Clone, PartialEq)]
pub struct LuminanceStats {
    /// Pixels counted (positive luminance, inside the mask).
    pub count: u64,
    /// Pixels inside the mask whose luminance is zero (or NaN/negative, treated as zero).
    pub zero_count: u64,
    /// Geometric mean `exp(mean(ln L))` over positive, finite luminance, or 0 when there is none.
    pub log_average: f64,
    /// Smallest positive luminance (0 when `count == 0`).
    pub min: f64,
    /// Largest finite luminance (0 when `count == 0`).
    pub max: f64,
    hist: Vec<u64>,
}

impl LuminanceStats {
    /// The `p`-th percentile (`p` in percent, clamped to [0, 100]) of positive luminance,
    /// resolved to 1/32 stop (≈2 %) and clamped to `[min, max]`; 0 when nothing was counted.
    pub fn percentile(&self, p: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let p = if p.is_nan() {
            50.0
        } else {
            p.clamp(0.0, 100.0)
        };
        let target = ((p / 100.0) * self.count as f64).ceil().max(1.0) as u64;
        let mut acc = 0u64;
        for (i, &n) in self.hist.iter().enumerate() {
            acc += n;
            if acc >= target {
                let log2 = HIST_MIN_LOG2 + (i as f64 + 0.5) / HIST_BINS_PER_STOP;
                return log2.exp2().clamp(self.min, self.max);
            }
        }
        self.max
    }

    /// Counts per 1/32-stop bin of log₂ luminance, starting at 2⁻⁶⁴ (4096 bins; values outside
    /// [2⁻⁶⁴, 2⁶⁴) are counted in the end bins).
    pub fn log2_histogram(&self) -> &[u64] {
        &self.hist
    }

    /// Dynamic range `log₂(max / min)` in stops (0 when fewer than one positive pixel).
    pub fn dynamic_range_stops(&self) -> f64 {
        if self.count == 0 || self.min <= 0.0 {
            0.0
        } else {
            (self.max / self.min).log2()
        }
    }

    /// `log₂(P_hi / P_lo)` between two percentiles, the range that survives a few hot or dead
    /// pixels.
    pub fn robust_range_stops(&self, lo: f64, hi: f64) -> f64 {
        let (a, b) = (self.percentile(lo), self.percentile(hi));
        if a > 0.0 && b > 0.0 {
            (b / a).log2()
        } else {
            0.0
        }
    }
}

/// Per-channel and luminance statistics of a whole radiance map, from one pass (what
/// `skydome info` prints).
#[derive(Debug, Clone, PartialEq)]
pub struct RadianceStats {
    /// Per-channel (R, G, B) minimum over valid pixels (`+∞` when there is none).
    pub min: [f32; 3],
    /// Per-channel maximum over valid pixels (`-∞` when there is none).
    pub max: [f32; 3],
    /// Per-channel mean over valid pixels (0 when there is none).
    pub mean: [f64; 3],
    /// Pixels with a NaN, infinite or negative channel; left out of `min`, `max` and `mean`.
    pub invalid_pixels: u64,
    /// Luminance statistics over every pixel (see [`LuminanceStats`] for how invalid values
    /// count there).
    pub luminance: LuminanceStats,
}

/// `log₂ x` for positive, finite `x` ([`crate::fastmath::log2`], error below 3·10⁻⁶);
/// subnormals go through the standard `log2`.
#[inline(always)]
pub(crate) fn fast_log2(x: f32) -> f32 {
    if x < f32::MIN_POSITIVE {
        return log2_subnormal(x);
    }
    log2_normal(x)
}

/// The standard `log2`, out of line. Inline, `x.log2()` is LLVM's `llvm.log2` intrinsic, which
/// may be executed speculatively: in a loop with a branch to it for the rare subnormal, LLVM
/// made the call unconditional and selected its result, and on wasm32 (where `log2f` is a
/// software routine, not the C library's) that call for every pixel cost the browser's tone map
/// about 30 ms of CPU on 12 MP. A call to an ordinary function is not speculated.
#[cold]
#[inline(never)]
fn log2_subnormal(x: f32) -> f32 {
    x.log2()
}

use crate::fastmath::log2 as log2_normal;

/// How pixels are weighted in the statistics.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Weights {
    /// Every pixel (inside the optional hard mask) counts once.
    Uniform(Option<Circle>),
    /// Sky weighting inside a dome circle: full weight within `inner · r` of the centre, falling
    /// linearly in `r²` (area) to zero at `outer · r`, zero beyond (module docs of [`super`]).
    /// Only every `stride`-th pixel of every `stride`-th row is measured.
    Radial {
        circle: Circle,
        inner: f64,
        outer: f64,
        stride: usize,
    },
}

#[derive(Clone)]
struct Acc {
    count: u64,
    inf: u64,
    zero: u64,
    sum_log2: f64,
    min: f32,
    max: f32,
    hist: Vec<u64>,
    // Per-channel statistics, only gathered for `radiance_stats`.
    ch_min: [f32; 3],
    ch_max: [f32; 3],
    ch_sum: [f64; 3],
    invalid: u64,
}

impl Acc {
    fn new() -> Self {
        Self {
            count: 0,
            inf: 0,
            zero: 0,
            sum_log2: 0.0,
            min: f32::INFINITY,
            max: 0.0,
            hist: vec![0; HIST_BINS],
            ch_min: [f32::INFINITY; 3],
            ch_max: [f32::NEG_INFINITY; 3],
            ch_sum: [0.0; 3],
            invalid: 0,
        }
    }

    /// Adds the pixels of one row span with weight `w` each (`px` holds whole RGB triples).
    ///
    /// Works in blocks of 64 pixels and three passes — luminance, log₂, then the branchy
    /// bookkeeping — so the first two have no branches and vectorise; one pass per pixel would
    /// leave the polynomial's chain of dependent multiply-adds waiting on each other.
    #[inline]
    fn add_span(&mut self, px: &[f32], w: u32) {
        const B: usize = 64;
        let mut lum = [0.0f32; B];
        let mut lg = [0.0f32; B];
        // Sums of logs over one span stay in f32 (a span is at most a row: ≤ 32767 values of
        // magnitude ≤ 128, so the relative error stays ~1e-4 stops), then go to f64.
        let mut row_sum = 0.0f32;
        let mut row_n = 0u64;
        let mut lo = self.min;
        let mut hi = self.max;
        let wt = u64::from(w);
        for chunk in px.chunks(3 * B) {
            let n = chunk.len() / 3;
            for (l, p) in lum.iter_mut().zip(chunk.chunks_exact(3)) {
                *l = luminance([max(p[0], 0.0), max(p[1], 0.0), max(p[2], 0.0)]);
            }
            for (g, l) in lg[..n].iter_mut().zip(&lum[..n]) {
                // `l` is a number (its channels are, and not negative).
                *g = log2_normal(max(*l, f32::MIN_POSITIVE));
            }
            for (&l, &g) in lum[..n].iter().zip(&lg[..n]) {
                if l > 0.0 && l < f32::INFINITY {
                    let g = if l < f32::MIN_POSITIVE {
                        log2_subnormal(l)
                    } else {
                        g
                    };
                    row_sum += g;
                    row_n += 1;
                    lo = min(l, lo);
                    hi = max(l, hi);
                    let bin = ((g - HIST_MIN_LOG2 as f32) * HIST_BINS_PER_STOP as f32)
                        .clamp(0.0, (HIST_BINS - 1) as f32) as usize;
                    self.hist[bin] += wt;
                } else if l == f32::INFINITY {
                    // Brightest possible value: top of the histogram, out of the mean.
                    self.inf += wt;
                    self.hist[HIST_BINS - 1] += wt;
                } else {
                    self.zero += wt;
                }
            }
        }
        self.min = lo;
        self.max = hi;
        self.count += row_n * wt;
        self.sum_log2 += f64::from(row_sum) * f64::from(w);
    }

    /// One pixel with weight `w` (1..=FULL_WEIGHT).
    #[inline(always)]
    fn add_one(&mut self, p: &[f32], w: u32) {
        let l = luminance([max(p[0], 0.0), max(p[1], 0.0), max(p[2], 0.0)]);
        if l > 0.0 && l < f32::INFINITY {
            let lg = fast_log2(l);
            self.count += u64::from(w);
            self.sum_log2 += f64::from(lg * w as f32);
            self.min = min(l, self.min);
            self.max = max(l, self.max);
            let bin = ((lg - HIST_MIN_LOG2 as f32) * HIST_BINS_PER_STOP as f32)
                .clamp(0.0, (HIST_BINS - 1) as f32) as usize;
            self.hist[bin] += u64::from(w);
        } else if l == f32::INFINITY {
            self.inf += u64::from(w);
            self.hist[HIST_BINS - 1] += u64::from(w);
        } else {
            self.zero += u64::from(w);
        }
    }

    /// Per-channel minimum, maximum and sum. Four pixels (12 samples) at a time into 12
    /// lanes of accumulators, so the common all-valid case has no branch per sample and
    /// vectorises; a group holding an invalid sample goes pixel by pixel.
    #[inline]
    fn add_channels(&mut self, px: &[f32]) {
        let mut lo = [f32::INFINITY; 12];
        let mut hi = [f32::NEG_INFINITY; 12];
        let mut sum = [0.0f32; 12];
        let groups = px.chunks_exact(12);
        let tail = groups.remainder();
        let mut slow = |p: &[f32], lo: &mut [f32; 12], hi: &mut [f32; 12], sum: &mut [f32; 12]| {
            for q in p.chunks_exact(3) {
                // NaN fails every comparison, so `!(v >= 0 && v < ∞)` catches it too.
                if q.iter().all(|v| *v >= 0.0 && *v < f32::INFINITY) {
                    for c in 0..3 {
                        lo[c] = lo[c].min(q[c]);
                        hi[c] = hi[c].max(q[c]);
                        sum[c] += q[c];
                    }
                } else {
                    self.invalid += 1;
                }
            }
        };
        for g in groups {
            let ok = g
                .iter()
                .fold(true, |ok, v| ok & (*v >= 0.0) & (*v < f32::INFINITY));
            if ok {
                for i in 0..12 {
                    lo[i] = lo[i].min(g[i]);
                    hi[i] = hi[i].max(g[i]);
                    sum[i] += g[i];
                }
            } else {
                slow(g, &mut lo, &mut hi, &mut sum);
            }
        }
        slow(tail, &mut lo, &mut hi, &mut sum);
        for (i, ((l, h), s)) in lo.iter().zip(&hi).zip(&sum).enumerate() {
            let c = i % 3;
            self.ch_min[c] = self.ch_min[c].min(*l);
            self.ch_max[c] = self.ch_max[c].max(*h);
            self.ch_sum[c] += f64::from(*s);
        }
    }

    #[cfg(feature = "parallel")]
    fn merge(mut self, o: Acc) -> Acc {
        self.count += o.count;
        self.inf += o.inf;
        self.zero += o.zero;
        self.sum_log2 += o.sum_log2;
        self.min = self.min.min(o.min);
        self.max = self.max.max(o.max);
        for (a, b) in self.hist.iter_mut().zip(&o.hist) {
            *a += b;
        }
        for c in 0..3 {
            self.ch_min[c] = self.ch_min[c].min(o.ch_min[c]);
            self.ch_max[c] = self.ch_max[c].max(o.ch_max[c]);
            self.ch_sum[c] += o.ch_sum[c];
        }
        self.invalid += o.invalid;
        self
    }

    fn finish(self) -> LuminanceStats {
        // `count` holds finite positive pixels; infinities were counted apart.
        let finite = self.count;
        let count = self.count + self.inf;
        LuminanceStats {
            count,
            zero_count: self.zero,
            log_average: if finite > 0 {
                (self.sum_log2 / finite as f64).exp2()
            } else {
                0.0
            },
            min: if finite > 0 && self.min.is_finite() {
                f64::from(self.min)
            } else {
                0.0
            },
            max: if finite > 0 { f64::from(self.max) } else { 0.0 },
            hist: self.hist,
        }
    }
}

/// Runs `row(acc, y, row_samples)` over every row, in parallel bands when possible.
fn fold_rows(img: &HdrImage, row: impl Fn(&mut Acc, usize, &[f32]) + Sync) -> Acc {
    let w = img.width;
    #[cfg(feature = "parallel")]
    {
        // Bands of rows keep the number of per-task histograms small.
        let band = img.height.div_ceil(16).max(1);
        img.data
            .par_chunks(3 * w * band)
            .enumerate()
            .map(|(b, chunk)| {
                let mut acc = Acc::new();
                for (i, r) in chunk.chunks_exact(3 * w).enumerate() {
                    row(&mut acc, b * band + i, r);
                }
                acc
            })
            .reduce(Acc::new, Acc::merge)
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut acc = Acc::new();
        for (y, r) in img.data.chunks_exact(3 * w).enumerate() {
            row(&mut acc, y, r);
        }
        acc
    }
}

/// Luminance statistics of `img` over the pixels inside `mask` (all pixels when `None`).
pub fn luminance_stats(
    img: &HdrImage,
    mask: Option<&Circle>,
) -> Result<LuminanceStats, TonemapError> {
    weighted_stats(img, Weights::Uniform(mask.copied()))
}

/// Per-channel minimum, maximum and mean, the count of invalid pixels, and the luminance
/// statistics of the whole image, in one pass.
pub fn radiance_stats(img: &HdrImage) -> Result<RadianceStats, TonemapError> {
    check_image(img)?;
    let acc = fold_rows(img, |acc, _, r| {
        acc.add_span(r, 1);
        acc.add_channels(r);
    });
    let valid = img.pixel_count() as u64 - acc.invalid;
    let mean = acc
        .ch_sum
        .map(|s| if valid > 0 { s / valid as f64 } else { 0.0 });
    Ok(RadianceStats {
        min: acc.ch_min,
        max: acc.ch_max,
        mean,
        invalid_pixels: acc.invalid,
        luminance: acc.finish(),
    })
}

/// Statistics with per-pixel integer weights (counts are sums of weights, [`FULL_WEIGHT`] per
/// fully weighted pixel under [`Weights::Radial`], 1 under [`Weights::Uniform`]).
pub(crate) fn weighted_stats(img: &HdrImage, wts: Weights) -> Result<LuminanceStats, TonemapError> {
    check_image(img)?;
    let w = img.width;
    let acc = match wts {
        Weights::Uniform(mask) => fold_rows(img, |acc, y, r| {
            let (x0, x1) = row_span(mask.as_ref(), w, y);
            acc.add_span(&r[3 * x0..3 * x1], 1);
        }),
        Weights::Radial {
            circle,
            inner,
            outer,
            stride,
        } => {
            let stride = stride.max(1);
            let (r2_in, r2_out) = ((circle.r * inner).powi(2), (circle.r * outer).powi(2));
            let scale = f64::from(FULL_WEIGHT) / (r2_out - r2_in).max(f64::MIN_POSITIVE);
            let edge = Circle {
                r: circle.r * outer,
                ..circle
            };
            fold_rows(img, |acc, y, r| {
                if y % stride != 0 {
                    return;
                }
                let (e0, e1) = row_span(Some(&edge), w, y);
                let dy = y as f64 + 0.5 - circle.cy;
                // Start on the stride grid so every row samples the same columns.
                let first = e0.div_ceil(stride) * stride;
                for x in (first..e1).step_by(stride) {
                    let dx = x as f64 + 0.5 - circle.cx;
                    let r2 = dx * dx + dy * dy;
                    let wt = if r2 <= r2_in {
                        FULL_WEIGHT
                    } else {
                        ((r2_out - r2) * scale + 0.5).clamp(0.0, f64::from(FULL_WEIGHT)) as u32
                    };
                    if wt > 0 {
                        acc.add_one(&r[3 * x..3 * x + 3], wt);
                    }
                }
            })
        }
    };
    Ok(acc.finish())
}

pub(crate) fn check_image<T>(img: &RgbImage<T>) -> Result<(), TonemapError> {
    let expected = img
        .width
        .checked_mul(img.height)
        .and_then(|n| n.checked_mul(3));
    if expected != Some(img.data.len()) {
        return Err(TonemapError::BadBuffer {
            width: img.width,
            height: img.height,
            len: img.data.len(),
            expected: expected.unwrap_or(usize::MAX),
        });
    }
    if img.width == 0 || img.height == 0 {
        return Err(TonemapError::EmptyImage);
    }
    Ok(())
}

/// Row mask: the `[x0, x1)` span of row `y` inside the circle (the whole row without a mask);
/// see [`Circle::row_span`].
#[inline]
pub(crate) fn row_span(mask: Option<&Circle>, width: usize, y: usize) -> (usize, usize) {
    mask.map_or((0, width), |c| c.row_span(y, width))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_log2_is_within_3e6_stops_of_log2() {
        let mut worst = 0.0f64;
        let mut x = 1e-30f32;
        while x < 1e30 {
            let e = (f64::from(fast_log2(x)) - f64::from(x).log2()).abs();
            worst = worst.max(e);
            x *= 1.013;
        }
        assert!(worst < 3e-6 * 8.0, "worst {worst}");
        assert_eq!(fast_log2(1.0), 0.0);
        assert!((fast_log2(1e-40) - 1e-40f32.log2()).abs() < 1e-5);
    }

    #[test]
    fn mask_row_span_matches_contains_pixel() {
        let c = Circle {
            cx: 10.3,
            cy: 7.9,
            r: 6.2,
        };
        for y in 0..20 {
            let (x0, x1) = row_span(Some(&c), 25, y);
            for x in 0..25 {
                assert_eq!((x0..x1).contains(&x), c.contains_pixel(x, y), "({x},{y})");
            }
        }
    }

    #[test]
    fn percentile_resolves_to_a_thirty_second_of_a_stop() {
        let data: Vec<f32> = (1..=1000)
            .flat_map(|i| {
                let v = i as f32;
                [v, v, v]
            })
            .collect();
        let img = HdrImage::from_vec(1000, 1, data).unwrap();
        let s = luminance_stats(&img, None).unwrap();
        let p = s.percentile(50.0);
        assert!((p / 500.0 - 1.0).abs() < 0.025, "median {p}");
        assert_eq!(s.count, 1000);
        assert!((s.max - 1000.0).abs() < 1e-3 && (s.min - 1.0).abs() < 1e-6);
    }

    #[test]
    fn radial_weights_ignore_the_rim_and_count_the_centre() {
        // Bright centre, dark rim: the radial log-average is the centre's.
        let (w, h) = (101, 101);
        let mut data = Vec::with_capacity(3 * w * h);
        for y in 0..h {
            for x in 0..w {
                let rho = ((x as f64 - 50.0).powi(2) + (y as f64 - 50.0).powi(2)).sqrt() / 50.5;
                let v = if rho < 0.5 { 1.0 } else { 1e-3 };
                data.extend([v, v, v]);
            }
        }
        let img = HdrImage::from_vec(w, h, data).unwrap();
        let c = Circle {
            cx: 50.5,
            cy: 50.5,
            r: 50.5,
        };
        let s = weighted_stats(
            &img,
            Weights::Radial {
                circle: c,
                inner: 0.5,
                outer: 0.5001,
                stride: 1,
            },
        )
        .unwrap();
        assert!((s.log_average - 1.0).abs() < 1e-3, "{}", s.log_average);
        let u = luminance_stats(&img, None).unwrap();
        assert!(u.log_average < 0.1);
    }

    #[test]
    fn radiance_stats_count_invalid_pixels_and_channel_extremes() {
        let img = HdrImage::from_vec(3, 1, vec![1.0, 2.0, 3.0, f32::NAN, 1.0, 1.0, 4.0, 0.5, 0.0])
            .unwrap();
        let s = radiance_stats(&img).unwrap();
        assert_eq!(s.invalid_pixels, 1);
        assert_eq!(s.min, [1.0, 0.5, 0.0]);
        assert_eq!(s.max, [4.0, 2.0, 3.0]);
        assert!((s.mean[0] - 2.5).abs() < 1e-9);
        assert_eq!(s.luminance.count, 3);
    }
}
