//! Comparing two radiance maps (e.g. a merge against ground truth or another tool's output).
//!
//! [`compare`]`(a, b, mask, opts)` treats `b` as the reference. Only values where the mask
//! (if any) is true and both images are finite and strictly positive take part; metrics pool
//! the three channels (one sample = one channel of one pixel).
//!
//! 1. **Scale.** Radiance from a bracket is relative, so one global factor `s` is fitted first:
//!    least squares in the log domain, `ln s = mean(ln b − ln a)` (or one `s_c` per channel with
//!    [`CompareOptions::per_channel_scale`], which also absorbs a white-balance difference).
//! 2. **Relative errors** `|s·a − b| / b`: median and 95th percentile (nearest-rank).
//! 3. **log2 RMSE** `sqrt(mean((log2(s·a) − log2 b)²))`, in stops.
//! 4. **The seed's eq. 5 (§9.1)**: each image is normalised by its own mean per channel over the
//!    included values, `a' = a_c / mean(a_c)`, `b' = b_c / mean(b_c)`, and the result is the
//!    (population) standard deviation of `a' − b'` over all included values. It needs no scale
//!    fit, but is dominated by the brightest pixels.
//! 5. **The seed's ρ (§9.1)**: each image is tone-mapped by the seed's per-channel min–max
//!    operator, `(v − min_c) / (max_c − min_c)` over the included values (so both lie in
//!    `[0, 1]`), and ρ is the (population) standard deviation of the per-value difference. This
//!    is the number the seed reports (0.011–0.016 for its merges); eq. 5 above is not bounded
//!    and gives values like 17 on a sky with a sun.
//!
//! [`well_exposed_mask`] gives the usual mask: pixels seen well exposed in at least one frame.

use crate::bracket::Frame;
use crate::image::HdrImage;
use crate::sampling::code8;

/// Errors from [`compare`].
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CompareError {
    /// Images or mask differ in size.
    #[error("images are {0}x{1} and {2}x{3} (or the mask length {4} does not match): compare images of the same size")]
    SizeMismatch(usize, usize, usize, usize, usize),
    /// No pixel is usable.
    #[error("no pixel is positive and finite in both images inside the mask: nothing to compare")]
    Empty,
}

/// Options for [`compare`].
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CompareOptions {
    /// Fit one scale per channel instead of one for all.
    pub per_channel_scale: bool,
}

/// The numbers [`compare`] reports.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CompareReport {
    /// Pixels that took part (all three channels usable).
    pub pixels: usize,
    /// Fitted scale per channel applied to `a` (all equal without per-channel scale).
    pub scale: [f64; 3],
    /// The seed's eq. 5: std of the difference of mean-normalised images.
    pub normalised_std: f64,
    /// The seed's ρ: std of the difference of the two min–max tone-mapped images in `[0, 1]`.
    pub tonemapped_std: f64,
    /// Median relative error after scaling.
    pub median_rel_error: f64,
    /// 95th-percentile relative error after scaling.
    pub p95_rel_error: f64,
    /// RMS of the log2 ratio after scaling, in stops.
    pub log2_rmse: f64,
    /// With `a`'s standard-error map ([`with_standard_error`]): the median over the compared
    /// pixels of its stated standard error (largest channel), stops.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_standard_error_stops: Option<f64>,
    /// With `a`'s standard-error map: the median of `|log2(s·a / b)| / σ` over the compared
    /// values with a finite σ — 0.674 when the stated error is honest and `b` is exact, larger
    /// when `a` is worse than it says.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_error_in_sigmas: Option<f64>,
}

/// Adds to `report` (from [`compare`] of `a` against `b` inside `mask`) what `a`'s
/// standard-error map `sigma` (stops per channel, `+∞` = not measured; see
/// [`crate::merge::standard_error`]) says: its median, and the actual error in units of it.
pub fn with_standard_error(
    report: &mut CompareReport,
    a: &HdrImage,
    b: &HdrImage,
    sigma: &HdrImage,
    mask: Option<&[bool]>,
) -> Result<(), CompareError> {
    let np = a.pixel_count();
    if sigma.width != a.width || sigma.height != a.height || sigma.data.len() != 3 * np {
        return Err(CompareError::SizeMismatch(
            a.width,
            a.height,
            sigma.width,
            sigma.height,
            mask.map_or(np, <[bool]>::len),
        ));
    }
    let ok = |v: f32| v.is_finite() && v > 0.0;
    let (mut stated, mut ratio) = (Vec::new(), Vec::new());
    for p in (0..np).filter(|&p| mask.is_none_or(|m| m.get(p) == Some(&true))) {
        let s = &sigma.data[3 * p..3 * p + 3];
        let worst = s.iter().copied().fold(0f32, f32::max);
        if worst.is_finite() {
            stated.push(f64::from(worst));
        }
        for (c, &sc) in s.iter().enumerate() {
            let (x, y) = (a.data[3 * p + c], b.data[3 * p + c]);
            if ok(x) && ok(y) && sc.is_finite() && sc > 0.0 {
                let e = (f64::from(x) * report.scale[c] / f64::from(y)).log2();
                ratio.push(e.abs() / f64::from(sc));
            }
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    report.median_standard_error_stops = median(&mut stated);
    report.median_error_in_sigmas = median(&mut ratio);
    Ok(())
}

/// Compares `a` against the reference `b` inside `mask` (row-major, one entry per pixel).
pub fn compare(
    a: &HdrImage,
    b: &HdrImage,
    mask: Option<&[bool]>,
    opts: &CompareOptions,
) -> Result<CompareReport, CompareError> {
    let np = a.pixel_count();
    if a.width != b.width
        || a.height != b.height
        || a.data.len() != 3 * np
        || b.data.len() != 3 * np
        || mask.is_some_and(|m| m.len() != np)
    {
        return Err(CompareError::SizeMismatch(
            a.width,
            a.height,
            b.width,
            b.height,
            mask.map_or(np, <[bool]>::len),
        ));
    }
    let ok = |v: f32| v.is_finite() && v > 0.0;
    let used: Vec<usize> = (0..np)
        .filter(|&p| mask.is_none_or(|m| m[p]))
        .filter(|&p| (0..3).all(|c| ok(a.data[3 * p + c]) && ok(b.data[3 * p + c])))
        .collect();
    if used.is_empty() {
        return Err(CompareError::Empty);
    }
    let n = used.len() as f64;
    let mut log_diff = [0.0f64; 3];
    let mut mean_a = [0.0f64; 3];
    let mut mean_b = [0.0f64; 3];
    for &p in &used {
        for c in 0..3 {
            let (x, y) = (a.data[3 * p + c] as f64, b.data[3 * p + c] as f64);
            log_diff[c] += y.ln() - x.ln();
            mean_a[c] += x;
            mean_b[c] += y;
        }
    }
    let scale = if opts.per_channel_scale {
        log_diff.map(|d| (d / n).exp())
    } else {
        [((log_diff[0] + log_diff[1] + log_diff[2]) / (3.0 * n)).exp(); 3]
    };
    let mean_a = mean_a.map(|m| m / n);
    let mean_b = mean_b.map(|m| m / n);
    let mut rel = Vec::with_capacity(used.len() * 3);
    let (mut l2, mut d1, mut d2) = (0.0f64, 0.0f64, 0.0f64);
    for &p in &used {
        for c in 0..3 {
            let (x, y) = (a.data[3 * p + c] as f64, b.data[3 * p + c] as f64);
            let xs = x * scale[c];
            rel.push((xs - y).abs() / y);
            let l = (xs / y).log2();
            l2 += l * l;
            let d = x / mean_a[c] - y / mean_b[c];
            d1 += d;
            d2 += d * d;
        }
    }
    let m = rel.len() as f64;
    rel.sort_by(f64::total_cmp);
    let pct = |q: f64| rel[((q * m).ceil() as usize).clamp(1, rel.len()) - 1];
    let dm = d1 / m;
    // The seed's min–max operator per channel, then the std of the difference.
    let range = |img: &HdrImage, c: usize| {
        used.iter()
            .map(|&p| img.data[3 * p + c] as f64)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            })
    };
    let (ra, rb) = (
        [0, 1, 2].map(|c| range(a, c)),
        [0, 1, 2].map(|c| range(b, c)),
    );
    let unit = |v: f64, (lo, hi): (f64, f64)| if hi > lo { (v - lo) / (hi - lo) } else { 0.0 };
    let (mut t1, mut t2) = (0.0f64, 0.0f64);
    for &p in &used {
        for c in 0..3 {
            let d = unit(a.data[3 * p + c] as f64, ra[c]) - unit(b.data[3 * p + c] as f64, rb[c]);
            t1 += d;
            t2 += d * d;
        }
    }
    let tm = t1 / m;
    Ok(CompareReport {
        pixels: used.len(),
        scale,
        normalised_std: (d2 / m - dm * dm).max(0.0).sqrt(),
        tonemapped_std: (t2 / m - tm * tm).max(0.0).sqrt(),
        median_rel_error: pct(0.5),
        p95_rel_error: pct(0.95),
        log2_rmse: (l2 / m).sqrt(),
        median_standard_error_stops: None,
        median_error_in_sigmas: None,
    })
}

/// Pixels (row-major) that are well exposed — all three channels within `lo..=hi` (8-bit
/// codes; 16-bit input is binned) — in at least one frame. Frames of different sizes give an
/// error.
pub fn well_exposed_mask(frames: &[Frame], lo: u8, hi: u8) -> Result<Vec<bool>, CompareError> {
    let Some(first) = frames.first() else {
        return Ok(Vec::new());
    };
    let np = first.width * first.height;
    let mut mask = vec![false; np];
    for f in frames {
        if f.width != first.width || f.height != first.height || f.pixels.len() != 3 * np {
            return Err(CompareError::SizeMismatch(
                first.width,
                first.height,
                f.width,
                f.height,
                f.pixels.len() / 3,
            ));
        }
        for (p, m) in mask.iter_mut().enumerate() {
            if !*m {
                let v = code8(&f.pixels, 3 * p);
                *m = v.iter().all(|&z| z >= lo && z <= hi);
            }
        }
    }
    Ok(mask)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(v: &[f32]) -> HdrImage {
        HdrImage::from_vec(v.len() / 3, 1, v.to_vec()).unwrap()
    }

    #[test]
    fn scaled_copy_compares_as_identical() {
        let b = img(&[1.0, 2.0, 3.0, 0.5, 8.0, 100.0]);
        let a = img(&b.data.iter().map(|v| v * 7.5).collect::<Vec<_>>());
        let r = compare(&a, &b, None, &CompareOptions::default()).unwrap();
        assert!(r.log2_rmse < 1e-6 && r.median_rel_error < 1e-6 && r.normalised_std < 1e-6);
        assert!(r.tonemapped_std < 1e-7);
        assert!((r.scale[0] - 1.0 / 7.5).abs() < 1e-6);
        assert_eq!(r.pixels, 2);
    }

    #[test]
    fn seeds_rho_is_the_std_of_min_max_tonemapped_differences() {
        // a equals b except one red value, 3 instead of 2; both reds span 0.5..4 over the
        // used pixels, so that value differs by 1/3.5 after min–max and the other eight by 0.
        let b = img(&[0.5, 0.5, 0.5, 4.0, 4.0, 4.0, 2.0, 2.0, 2.0, 0.0, 0.0, 0.0]);
        let mut a = b.clone();
        a.data[6] = 3.0;
        let r = compare(&a, &b, None, &CompareOptions::default());
        // The all-zero pixel is excluded (not positive): three pixels, nine values.
        let r = r.unwrap();
        let d: f64 = 1.0 / 3.5;
        let want = (d * d / 9.0 - (d / 9.0).powi(2)).sqrt();
        assert!(
            (r.tonemapped_std - want).abs() < 1e-9,
            "{} vs {want}",
            r.tonemapped_std
        );
        assert!(r.tonemapped_std < 1.0);
    }

    #[test]
    fn one_stop_error_is_one_stop_rmse() {
        let b = img(&[1.0; 6]);
        let a = img(&[1.0, 1.0, 1.0, 4.0, 4.0, 4.0]);
        let r = compare(&a, &b, None, &CompareOptions::default()).unwrap();
        // Scale 1/2: half the values are 1/2 (−1 stop), half 2 (+1 stop).
        assert!((r.log2_rmse - 1.0).abs() < 1e-9);
        assert!((r.p95_rel_error - 1.0).abs() < 1e-9);
    }

    #[test]
    fn masked_nonpositive_and_nan_values_are_skipped() {
        let b = img(&[1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 2.0, 2.0, 2.0]);
        let a = img(&[1.0, 1.0, 1.0, 1.0, 1.0, 1.0, f32::NAN, 9.0, 9.0]);
        let r = compare(
            &a,
            &b,
            Some(&[true, true, true]),
            &CompareOptions::default(),
        )
        .unwrap();
        assert_eq!(r.pixels, 1);
        let e = compare(
            &a,
            &b,
            Some(&[false, true, true]),
            &CompareOptions::default(),
        );
        assert_eq!(e, Err(CompareError::Empty));
    }
}
