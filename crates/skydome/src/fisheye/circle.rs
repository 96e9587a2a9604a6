//! Detecting the lens's visible image circle (see the [module docs](super) for the method).

use serde::{Deserialize, Serialize};

use super::FisheyeError;
use crate::image::{Bilinear, Circle, RgbImage};

/// A fitted image circle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CircleFit {
    /// The visible circle (centre and radius in pixels).
    pub circle: Circle,
    /// RMS orthogonal distance of the inlier boundary points from the circle, pixels.
    pub residual_px: f64,
    /// Number of boundary points that support the fit (inliers).
    pub points: usize,
    /// Number of boundary points found before outlier rejection.
    pub candidates: usize,
}

/// Detects the lens's visible image circle in an 8-bit RGB image (use the best-exposed frame).
/// Uses the per-pixel maximum of R, G and B, so a saturated-blue sky and a red sunset horizon
/// both stand out from the housing. See the module docs for the method.
pub fn detect_circle(img: &RgbImage<u8>) -> Result<CircleFit, FisheyeError> {
    img.validate()?;
    detect_circle_rgb8(&img.data, img.width, img.height)
}

/// [`detect_circle`] on interleaved 8-bit RGB samples (`width * height * 3`, row-major, origin
/// top-left), borrowed: the pipeline runs it on a frame of the bracket without a copy.
pub(crate) fn detect_circle_rgb8(
    rgb: &[u8],
    width: usize,
    height: usize,
) -> Result<CircleFit, FisheyeError> {
    crate::image::check_samples(rgb.len(), width, height, 3)?;
    if width < 16 || height < 16 {
        return Err(FisheyeError::ImageTooSmall { width, height });
    }
    // The maximum of R, G and B per pixel, a band's rows at a time (no whole-image copy).
    let max_rgb = |y: usize, out: &mut [u8]| {
        let row = &rgb[3 * y * width..3 * (y + 1) * width];
        for (l, p) in out.iter_mut().zip(row.chunks_exact(3)) {
            *l = p[0].max(p[1]).max(p[2]);
        }
    };
    detect_in(&Blurred::from_rows(width, height, max_rgb))
}

/// [`detect_circle`] on a single-channel 8-bit image (`width * height` samples, row-major,
/// origin top-left).
pub fn detect_circle_luma(
    luma: &[u8],
    width: usize,
    height: usize,
) -> Result<CircleFit, FisheyeError> {
    if width < 16 || height < 16 {
        return Err(FisheyeError::ImageTooSmall { width, height });
    }
    crate::image::check_samples(luma.len(), width, height, 1)?;
    let img = Blurred::from_rows(width, height, |y, out: &mut [u8]| {
        out.copy_from_slice(&luma[y * width..(y + 1) * width]);
    });
    detect_in(&img)
}

/// The circle in a blurred image (at least 16 × 16).
fn detect_in(img: &Blurred) -> Result<CircleFit, FisheyeError> {
    let (width, height) = (img.w, img.h);
    let (housing, threshold) = housing_threshold(img);

    // Rough centre: centroid of the pixels above threshold (whole pixel sums, exact in u64).
    let above = img.first_sum_above(threshold);
    let row_sums = |(y, row): (usize, &[u16])| {
        let (mut n, mut sx) = (0u64, 0u64);
        for (x, &s) in row.iter().enumerate() {
            if s >= above {
                n += 1;
                sx += x as u64;
            }
        }
        (n, sx, n * y as u64)
    };
    let add = |a: (u64, u64, u64), b: (u64, u64, u64)| (a.0 + b.0, a.1 + b.1, a.2 + b.2);
    #[cfg(feature = "parallel")]
    let (n, sx, sy) = {
        use rayon::prelude::*;
        img.sums
            .par_chunks(width)
            .enumerate()
            .map(row_sums)
            .reduce(|| (0, 0, 0), add)
    };
    #[cfg(not(feature = "parallel"))]
    let (n, sx, sy) = img
        .sums
        .chunks(width)
        .enumerate()
        .map(row_sums)
        .fold((0, 0, 0), add);
    if n < 16 {
        return Err(FisheyeError::NoCircle { points: 0 });
    }
    let cnt = n as f64;
    // Σ(x + 0.5) / n, as the pixel centres' mean (every sum is exact in f64).
    let mut centre = ((sx as f64 + 0.5 * cnt) / cnt, (sy as f64 + 0.5 * cnt) / cnt);
    let mut best: Option<CircleFit> = None;
    // Two passes: the centroid is biased when the circle is cut by the frame; rays cast from the
    // first fit's centre meet the boundary more squarely.
    for _ in 0..2 {
        let pts = boundary_points(img, centre, housing, threshold);
        let fit = robust_circle_fit(&pts)?;
        centre = (fit.circle.cx, fit.circle.cy);
        best = Some(fit);
    }
    let fit = best.ok_or(FisheyeError::NoCircle { points: 0 })?;
    if !plausible(&fit.circle, width, height) {
        return Err(FisheyeError::NoCircle { points: fit.points });
    }
    doubt_housing(img, housing, &fit.circle)?;
    Ok(fit)
}

/// A lens's picture circle has its centre on the image and a radius no larger than the image's
/// diagonal (a circle cut by the frame is still centred on it). Boundary points that lie
/// nearly on a line (a test pattern's straight edge) fit a circle millions of pixels wide
/// centred far off the image; the housing check cannot judge it (no grid point of the image
/// falls inside 0.9 of such a circle), so it is refused here.
fn plausible(c: &Circle, width: usize, height: usize) -> bool {
    let (w, h) = (width as f64, height as f64);
    c.r.is_finite()
        && c.r > 0.0
        && c.r <= w.hypot(h)
        && (0.0..=w).contains(&c.cx)
        && (0.0..=h).contains(&c.cy)
}

/// The corners' level may be at most this fraction of the median level inside the circle.
/// A lens housing passes no light: on the best-exposed frame of a real fish-eye it is a few
/// percent of the sky's level (the Alpnach all-sky frames and the synthetic domes pass), while a
/// test pattern's or an ordinary photo's round object sits on a background about as bright as
/// itself (Chromium's fake camera: 50 %).
const HOUSING_MAX_FRACTION: f32 = 0.35;

/// Doubts a fitted circle that has no dark housing around it: [`FisheyeError::NoHousing`] when
/// the corners' level (`housing`, the blurred value) exceeds [`HOUSING_MAX_FRACTION`] of the
/// median blurred level inside 0.9 of the circle's radius (sampled on a grid of about 64 × 64).
fn doubt_housing(img: &Blurred, housing: f32, c: &Circle) -> Result<(), FisheyeError> {
    let r = 0.9 * c.r;
    let step = ((r / 32.0).floor() as usize).max(1);
    let (x0, x1) = (
        (c.cx - r).max(0.0) as usize,
        ((c.cx + r).ceil() as usize).min(img.w),
    );
    let (y0, y1) = (
        (c.cy - r).max(0.0) as usize,
        ((c.cy + r).ceil() as usize).min(img.h),
    );
    let mut inside = Vec::new();
    for y in (y0..y1).step_by(step) {
        for x in (x0..x1).step_by(step) {
            let (dx, dy) = (x as f64 + 0.5 - c.cx, y as f64 + 0.5 - c.cy);
            if dx * dx + dy * dy <= r * r {
                inside.push(img.sums[y * img.w + x]);
            }
        }
    }
    if inside.is_empty() {
        return Ok(());
    }
    let mid = inside.len() / 2;
    let level = Blurred::value(*inside.select_nth_unstable(mid).1);
    if housing > HOUSING_MAX_FRACTION * level {
        return Err(FisheyeError::NoHousing {
            housing_percent: f64::from(100.0 * housing / level.max(1.0 / 9.0)),
        });
    }
    Ok(())
}

/// The 3×3 box blur of an 8-bit image (edge pixels replicate), to tame sensor noise before
/// thresholding, kept as the window sums (`0..=9·255`, so the blurred value is `sum / 9`):
/// half the memory of `f32` values, a histogram instead of a sort for the percentiles, and an
/// integer threshold for the centroid.
struct Blurred {
    sums: Vec<u16>,
    w: usize,
    h: usize,
}

/// Largest 3×3 window sum of 8-bit samples.
const MAX_SUM: usize = 9 * 255;

impl Blurred {
    /// The blur of the `w × h` image whose row `y` `row(y, out)` writes into `out` (`w`
    /// samples). Bands of rows in parallel (with the `parallel` feature), each reading its rows
    /// and the one above and below into a small buffer of its own.
    fn from_rows(w: usize, h: usize, row: impl Fn(usize, &mut [u8]) + Sync) -> Self {
        const BAND: usize = 64;
        let mut sums = vec![0u16; w * h];
        let band = |(b, out): (usize, &mut [u16])| {
            let y0 = b * BAND;
            let y1 = y0 + out.len() / w;
            // Source rows y0 − 1 ..= y1 (clamped to the image: edge rows replicate).
            let first = y0.saturating_sub(1);
            let last = y1.min(h - 1);
            let mut src = vec![0u8; (last + 1 - first) * w];
            for (y, r) in (first..=last).zip(src.chunks_exact_mut(w)) {
                row(y, r);
            }
            let r = |yy: usize| &src[(yy - first) * w..][..w];
            let mut col = vec![0u16; w];
            for (y, out) in (y0..y1).zip(out.chunks_exact_mut(w)) {
                blur_row(
                    r(y.saturating_sub(1)),
                    r(y),
                    r((y + 1).min(h - 1)),
                    &mut col,
                    out,
                );
            }
        };
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            sums.par_chunks_mut(w * BAND).enumerate().for_each(band);
        }
        #[cfg(not(feature = "parallel"))]
        sums.chunks_mut(w * BAND).enumerate().for_each(band);
        Self { sums, w, h }
    }

    /// The blurred value of a window sum.
    #[inline]
    fn value(sum: u16) -> f32 {
        f32::from(sum) / 9.0
    }

    /// The smallest window sum whose value exceeds `threshold` (`MAX_SUM + 1` when none does).
    fn first_sum_above(&self, threshold: f32) -> u16 {
        (0..=MAX_SUM as u16)
            .find(|&s| Self::value(s) > threshold)
            .unwrap_or(MAX_SUM as u16 + 1)
    }
}

/// One row of the 3×3 window sums from the rows above (`a`), at (`b`) and below (`c`):
/// column sums of the three rows into `col`, then three columns of those (edges replicate).
/// Zipped slices, no index arithmetic per pixel, so both passes vectorise (w ≥ 16).
#[inline]
fn blur_row(a: &[u8], b: &[u8], c: &[u8], col: &mut [u16], out: &mut [u16]) {
    let w = out.len();
    for (((s, &a), &b), &c) in col.iter_mut().zip(a).zip(b).zip(c) {
        *s = u16::from(a) + u16::from(b) + u16::from(c);
    }
    out[0] = 2 * col[0] + col[1];
    out[w - 1] = col[w - 2] + 2 * col[w - 1];
    let inner = out[1..w - 1]
        .iter_mut()
        .zip(&col[..w - 2])
        .zip(&col[1..w - 1])
        .zip(&col[2..]);
    for (((o, &l), &m), &r) in inner {
        *o = l + m + r;
    }
}

/// Housing level (median of the four corner patches) and the image/housing threshold.
fn housing_threshold(img: &Blurred) -> (f32, f32) {
    let (w, h) = (img.w, img.h);
    let p = (w.min(h) / 20).max(2);
    let mut corner = Vec::with_capacity(4 * p * p);
    for (x0, y0) in [(0, 0), (w - p, 0), (0, h - p), (w - p, h - p)] {
        for y in y0..y0 + p {
            corner.extend_from_slice(&img.sums[y * w + x0..y * w + x0 + p]);
        }
    }
    corner.sort_unstable();
    let housing = Blurred::value(corner[corner.len() / 2]);
    let noise = Blurred::value(corner[(corner.len() * 9) / 10]) - housing;
    // The 95th percentile of every third pixel, from a histogram of the window sums (in
    // parallel parts with the `parallel` feature; each part starts on a multiple of 3, so the
    // parts count the same pixels as one pass).
    const PART: usize = 3 << 16;
    let count = |mut hist: Vec<usize>, part: &[u16]| {
        for &s in part.iter().step_by(3) {
            hist[usize::from(s)] += 1;
        }
        hist
    };
    #[cfg(feature = "parallel")]
    let hist = {
        use rayon::prelude::*;
        img.sums
            .par_chunks(PART)
            .fold(|| vec![0usize; MAX_SUM + 1], count)
            .reduce(
                || vec![0usize; MAX_SUM + 1],
                |mut a, b| {
                    a.iter_mut().zip(&b).for_each(|(a, b)| *a += b);
                    a
                },
            )
    };
    #[cfg(not(feature = "parallel"))]
    let hist = img.sums.chunks(PART).fold(vec![0usize; MAX_SUM + 1], count);
    let len = img.sums.len().div_ceil(3);
    let rank = (len * 95) / 100;
    let mut seen = 0usize;
    let mut p95 = MAX_SUM as u16;
    for (s, &c) in hist.iter().enumerate() {
        seen += c;
        if seen > rank {
            p95 = s as u16;
            break;
        }
    }
    let p95 = Blurred::value(p95);
    let t = housing + (0.1 * (p95 - housing)).max(3.0 * noise + 2.0);
    (housing, t)
}

/// The blurred image bilinearly sampled at `(x, y)` (continuous pixel coordinates).
#[inline]
fn bilinear1(img: &Blurred, x: f64, y: f64) -> f32 {
    let b = Bilinear::at(img.w, img.h, x, y);
    b.weighted_sum(b.idx.map(|i| Blurred::value(img.sums[i])))
}

/// Rays of [`boundary_points`], evenly spaced in angle.
const RAYS: usize = 720;

/// Edge points on rays walked inwards from the frame edge towards `centre`, in the order of
/// the rays. The rays are independent and run in parallel with the `parallel` feature: each
/// reads a column-like line of a frame-sized image, one cache miss per sample on most rays,
/// which made the walk about 10 ms of the lens stage's single thread on 12 MP.
fn boundary_points(
    img: &Blurred,
    centre: (f64, f64),
    housing: f32,
    threshold: f32,
) -> Vec<(f64, f64)> {
    let ray = |i: usize| boundary_point(img, centre, housing, threshold, i);
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        (0..RAYS).into_par_iter().filter_map(ray).collect()
    }
    #[cfg(not(feature = "parallel"))]
    (0..RAYS).filter_map(ray).collect()
}

/// The edge point on ray `i` of [`boundary_points`], if the ray crosses the threshold inside
/// the frame.
fn boundary_point(
    img: &Blurred,
    centre: (f64, f64),
    housing: f32,
    threshold: f32,
    i: usize,
) -> Option<(f64, f64)> {
    const STEP: f64 = 0.5;
    let (cx, cy) = centre;
    let (wf, hf) = (img.w as f64, img.h as f64);
    let a = i as f64 * std::f64::consts::TAU / RAYS as f64;
    let (dx, dy) = (a.cos(), a.sin());
    // Distance from centre to the frame edge (pixel-centre box) along the ray.
    let t_edge = to_edge(cx, dx, wf).min(to_edge(cy, dy, hf));
    if !(t_edge.is_finite() && t_edge > 4.0) {
        return None;
    }
    // Profile sampled from the frame edge inwards, as far as 8 samples past the first
    // above the threshold (all the crossing search below reads).
    let mut profile = Vec::new();
    let n = (t_edge / STEP) as usize;
    let mut first = None;
    for k in 0..=n {
        let t = t_edge - k as f64 * STEP;
        let v = bilinear1(img, cx + t * dx, cy + t * dy);
        profile.push(v);
        if first.is_none() && v > threshold {
            first = Some(k);
        }
        if first.is_some_and(|f| k + 1 >= f + 8) {
            break;
        }
    }
    let first = first?;
    // Starting inside the image means the circle is cut by the frame on this ray.
    if first < 3 {
        return None;
    }
    // Local image level just inside the crossing, then the half-way crossing.
    let inner_end = (first + 8).min(profile.len());
    let local = profile[first..inner_end]
        .iter()
        .copied()
        .fold(0.0f32, f32::max);
    let half = 0.5 * (housing + local);
    let mut k = first;
    while k > 0 && profile[k - 1] >= half {
        k -= 1;
    }
    while k < profile.len() && profile[k] < half {
        k += 1;
    }
    if k == 0 || k >= profile.len() {
        return None;
    }
    let (v0, v1) = (profile[k - 1], profile[k]);
    let frac = if v1 > v0 {
        f64::from((half - v0) / (v1 - v0))
    } else {
        0.0
    };
    let t = t_edge - ((k - 1) as f64 + frac) * STEP;
    Some((cx + t * dx, cy + t * dy))
}

/// Distance along one axis from `c` to the pixel-centre box `0.5 ..= size − 0.5`, moving by `d`
/// per unit of the ray (∞ when `d` is 0).
fn to_edge(c: f64, d: f64, size: f64) -> f64 {
    if d > 0.0 {
        (size - 0.5 - c) / d
    } else if d < 0.0 {
        (0.5 - c) / d
    } else {
        f64::INFINITY
    }
}

/// Algebraic (Kåsa) least-squares circle through points: minimises Σ(x²+y²+Dx+Ey+F)².
fn kasa_fit(pts: &[(f64, f64)]) -> Option<Circle> {
    if pts.len() < 3 {
        return None;
    }
    // Centre the data for conditioning.
    let n = pts.len() as f64;
    let (mx, my) = pts
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    for &(x, y) in pts {
        let (u, v) = (x - mx, y - my);
        let row = nalgebra::Vector3::new(u, v, 1.0);
        ata += row * row.transpose();
        atb += row * (-(u * u + v * v));
    }
    let sol = ata.lu().solve(&atb)?;
    let (a, b) = (-0.5 * sol[0], -0.5 * sol[1]);
    let r2 = a * a + b * b - sol[2];
    (r2 > 0.0 && r2.is_finite()).then(|| Circle {
        cx: a + mx,
        cy: b + my,
        r: r2.sqrt(),
    })
}

/// Geometric circle fit (Gauss–Newton on orthogonal distances) from a starting circle.
fn geometric_fit(pts: &[(f64, f64)], start: Circle) -> Circle {
    let mut c = start;
    for _ in 0..20 {
        let mut jtj = nalgebra::Matrix3::<f64>::zeros();
        let mut jtr = nalgebra::Vector3::<f64>::zeros();
        for &(x, y) in pts {
            let (dx, dy) = (x - c.cx, y - c.cy);
            let d = (dx * dx + dy * dy).sqrt();
            if d < 1e-9 {
                continue;
            }
            let res = d - c.r;
            let j = nalgebra::Vector3::new(-dx / d, -dy / d, -1.0);
            jtj += j * j.transpose();
            jtr += j * res;
        }
        let Some(step) = jtj.lu().solve(&(-jtr)) else {
            break;
        };
        c.cx += step[0];
        c.cy += step[1];
        c.r += step[2];
        if step.norm() < 1e-6 {
            break;
        }
    }
    c
}

fn distance(c: &Circle, p: (f64, f64)) -> f64 {
    ((p.0 - c.cx).hypot(p.1 - c.cy) - c.r).abs()
}

/// RANSAC over point triples (deterministic xorshift seed) then geometric refinement on inliers.
fn robust_circle_fit(pts: &[(f64, f64)]) -> Result<CircleFit, FisheyeError> {
    if pts.len() < 8 {
        return Err(FisheyeError::NoCircle { points: pts.len() });
    }
    const ITERS: usize = 300;
    const INLIER_PX: f64 = 1.5;
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = |n: usize| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % n as u64) as usize
    };
    let mut best: Option<(usize, Circle)> = None;
    for _ in 0..ITERS {
        let tri = [
            pts[next(pts.len())],
            pts[next(pts.len())],
            pts[next(pts.len())],
        ];
        let Some(c) = kasa_fit(&tri) else { continue };
        // |d − r| < tol as a test on d², without a square root per point.
        let (lo, hi) = (c.r - INLIER_PX, c.r + INLIER_PX);
        let lo2 = if lo > 0.0 { lo * lo } else { -1.0 };
        let hi2 = hi * hi;
        let count = pts
            .iter()
            .filter(|p| {
                let d2 = (p.0 - c.cx).powi(2) + (p.1 - c.cy).powi(2);
                d2 > lo2 && d2 < hi2
            })
            .count();
        if best.is_none_or(|(b, _)| count > b) {
            best = Some((count, c));
        }
    }
    let (_, mut circle) = best.ok_or(FisheyeError::NoCircle { points: pts.len() })?;
    let mut inliers: Vec<(f64, f64)> = Vec::new();
    // Refine, re-select inliers with a threshold that follows the spread of the residuals.
    let mut tol = INLIER_PX;
    for _ in 0..4 {
        inliers = pts
            .iter()
            .copied()
            .filter(|&p| distance(&circle, p) < tol)
            .collect();
        if inliers.len() < 8 {
            return Err(FisheyeError::NoCircle {
                points: inliers.len(),
            });
        }
        let start = kasa_fit(&inliers).unwrap_or(circle);
        circle = geometric_fit(&inliers, start);
        let rms = rms_distance(&circle, &inliers);
        tol = (3.0 * rms).clamp(0.75, INLIER_PX);
    }
    if !(circle.r.is_finite() && circle.r > 2.0) {
        return Err(FisheyeError::NoCircle {
            points: inliers.len(),
        });
    }
    Ok(CircleFit {
        circle,
        residual_px: rms_distance(&circle, &inliers),
        points: inliers.len(),
        candidates: pts.len(),
    })
}

fn rms_distance(c: &Circle, pts: &[(f64, f64)]) -> f64 {
    let s: f64 = pts.iter().map(|&p| distance(c, p).powi(2)).sum();
    (s / pts.len().max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_circle_off_the_image_or_wider_than_its_diagonal_is_not_a_lens_circle() {
        let c = |cx, cy, r| Circle { cx, cy, r };
        // A real picture circle, one cut by the frame, and the fake camera's near-line fit
        // (radius 74 million pixels) on a 640 × 480 frame.
        assert!(plausible(&c(320.0, 240.0, 230.0), 640, 480));
        assert!(plausible(&c(320.0, 240.0, 390.0), 640, 480));
        assert!(!plausible(&c(320.0, 240.0, 74_250_743.0), 640, 480));
        assert!(!plausible(&c(-5.0e7, 240.0, 5.0e7), 640, 480));
        assert!(!plausible(&c(320.0, 240.0, f64::NAN), 640, 480));
        assert!(!plausible(&c(320.0, 240.0, 0.0), 640, 480));
    }

    #[test]
    fn a_straight_bright_edge_is_no_lens_circle() {
        // The left half lit, the right half dark: boundary points on a line.
        let (w, h) = (640usize, 480usize);
        let luma: Vec<u8> = (0..w * h)
            .map(|i| if i % w < w / 2 { 200 } else { 0 })
            .collect();
        match detect_circle_luma(&luma, w, h) {
            Err(FisheyeError::NoCircle { .. } | FisheyeError::NoHousing { .. }) => {}
            other => panic!("{other:?}"),
        }
    }
}
