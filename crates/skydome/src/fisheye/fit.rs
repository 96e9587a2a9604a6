//! Fitting a projection to measured `(angle, radius)` pairs, with model choice by AICc.

use serde::{Deserialize, Serialize};

use super::{FisheyeError, LensKind, Projection};

/// One lens measurement: a ray at `angle_deg` degrees from the optical axis landed
/// `radius_px` pixels from the image-circle centre.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AngleRadius {
    /// Angle from the optical axis in degrees, `[0, 180)`.
    pub angle_deg: f64,
    /// Distance from the optical centre in pixels.
    pub radius_px: f64,
}

/// One model fitted to lens measurements, with its residuals (pixels).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModelFit {
    /// The fitted projection.
    pub projection: Projection,
    /// Root-mean-square radial residual in pixels.
    pub rms_px: f64,
    /// Largest absolute radial residual in pixels.
    pub max_px: f64,
    /// Small-sample Akaike information criterion used by the automatic choice (lower is better).
    pub aicc: f64,
}

/// The result of [`fit_projection`]: the chosen model and every candidate that could be fitted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LensFit {
    /// The chosen fit (the requested model, or the lowest AICc).
    pub best: ModelFit,
    /// All models fitted, in [`LensKind::ALL`] order (models that cannot be fitted are left out).
    pub candidates: Vec<ModelFit>,
}

/// Fits every projection model to measured `(angle°, radius px)` pairs and picks `choice`, or the
/// model with the lowest AICc when `choice` is `None` (see the module docs).
///
/// Errors on invalid samples, when fewer than one (one-parameter models) or three (polynomial)
/// distinct non-zero angles are given, and when the requested model cannot be fitted.
pub fn fit_projection(
    samples: &[AngleRadius],
    choice: Option<LensKind>,
) -> Result<LensFit, FisheyeError> {
    let mut pts = Vec::with_capacity(samples.len());
    for (index, s) in samples.iter().enumerate() {
        if !(s.angle_deg.is_finite()
            && (0.0..180.0).contains(&s.angle_deg)
            && s.radius_px.is_finite()
            && s.radius_px >= 0.0)
        {
            return Err(FisheyeError::BadSample {
                index,
                angle_deg: s.angle_deg,
                radius_px: s.radius_px,
            });
        }
        pts.push((s.angle_deg.to_radians(), s.radius_px));
    }
    let mut distinct: Vec<f64> = pts.iter().map(|p| p.0).filter(|&t| t > 0.0).collect();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let n_distinct = distinct.len();
    let theta_max = pts.iter().map(|p| p.0).fold(0.0, f64::max);

    let mut candidates = Vec::new();
    let mut requested_err = None;
    for kind in LensKind::ALL {
        let fitted = fit_one(kind, &pts, n_distinct, theta_max);
        match fitted {
            Ok(fit) => candidates.push(fit),
            Err(e) if Some(kind) == choice => requested_err = Some(e),
            Err(_) => {}
        }
    }
    if let Some(e) = requested_err {
        return Err(e);
    }
    let best = match choice {
        Some(kind) => candidates
            .iter()
            .find(|c| c.projection.kind() == kind)
            .copied(),
        None => candidates
            .iter()
            .min_by(|a, b| a.aicc.total_cmp(&b.aicc))
            .copied(),
    }
    .ok_or(FisheyeError::TooFewSamples {
        model: choice.unwrap_or(LensKind::Equidistant),
        needed: 1,
        got: n_distinct,
    })?;
    Ok(LensFit { best, candidates })
}

fn fit_one(
    kind: LensKind,
    pts: &[(f64, f64)],
    n_distinct: usize,
    theta_max: f64,
) -> Result<ModelFit, FisheyeError> {
    let projection = if kind == LensKind::Polynomial {
        if n_distinct < 3 {
            return Err(FisheyeError::TooFewSamples {
                model: kind,
                needed: 3,
                got: n_distinct,
            });
        }
        // Columns θ, θ³, θ⁵ are scaled by their norms first: at θ ≈ 2 rad the raw normal matrix
        // spans four orders of magnitude and loses digits needlessly.
        let mut ata = nalgebra::Matrix3::<f64>::zeros();
        let mut atb = nalgebra::Vector3::<f64>::zeros();
        for &(t, r) in pts {
            let row = nalgebra::Vector3::new(t, t.powi(3), t.powi(5));
            ata += row * row.transpose();
            atb += row * r;
        }
        let scale = nalgebra::Vector3::from_fn(|i, _| {
            let d = ata[(i, i)];
            if d > 0.0 {
                1.0 / d.sqrt()
            } else {
                1.0
            }
        });
        let s = nalgebra::Matrix3::from_diagonal(&scale);
        let k = (s * ata * s)
            .cholesky()
            .map(|c| s * c.solve(&(s * atb)))
            .ok_or(FisheyeError::TooFewSamples {
                model: kind,
                needed: 3,
                got: n_distinct,
            })?;
        Projection::Polynomial {
            k1: k[0],
            k3: k[1],
            k5: k[2],
        }
    } else {
        if n_distinct < 1 {
            return Err(FisheyeError::TooFewSamples {
                model: kind,
                needed: 1,
                got: 0,
            });
        }
        if theta_max > kind.theta_limit() {
            return Err(FisheyeError::AngleOutOfModel {
                model: kind,
                theta_deg: theta_max.to_degrees(),
                limit_deg: kind.theta_limit().to_degrees(),
            });
        }
        let (mut num, mut den) = (0.0, 0.0);
        for &(t, r) in pts {
            let g = kind.unit_radius(t).unwrap_or(t);
            num += r * g;
            den += g * g;
        }
        Projection::with_focal(kind, num / den)
    };
    projection.validate(theta_max)?;
    let n = pts.len() as f64;
    let (mut rss, mut max) = (0.0f64, 0.0f64);
    for &(t, r) in pts {
        let e = projection.radius(t) - r;
        rss += e * e;
        max = max.max(e.abs());
    }
    let k = if kind == LensKind::Polynomial {
        3.0
    } else {
        1.0
    };
    const NOISE_FLOOR_PX: f64 = 0.01;
    let rss_floored = rss.max(n * NOISE_FLOOR_PX * NOISE_FLOOR_PX);
    let small_sample = if n - k - 1.0 > 0.0 {
        2.0 * k * (k + 1.0) / (n - k - 1.0)
    } else {
        // Not enough samples for the correction: make the model unattractive but still usable
        // when asked for by name.
        1e6
    };
    Ok(ModelFit {
        projection,
        rms_px: (rss / n).sqrt(),
        max_px: max,
        aicc: n * (rss_floored / n).ln() + 2.0 * k + small_sample,
    })
}

/// Parses lens measurements from CSV text: one `angle_deg,radius_px` pair a line (separated by
/// commas, semicolons, tabs or spaces), `#` comments and blank lines ignored, and a header line
/// such as `angle_deg,radius_px` skipped when it is the first line.
pub fn parse_angle_radius_csv(text: &str) -> Result<Vec<AngleRadius>, FisheyeError> {
    let mut v = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let nums: Option<Vec<f64>> = line
            .split([',', ';', '\t', ' '])
            .filter(|s| !s.is_empty())
            .map(|s| s.parse::<f64>().ok())
            .collect();
        match nums.as_deref() {
            Some([a, r]) => v.push(AngleRadius {
                angle_deg: *a,
                radius_px: *r,
            }),
            None if v.is_empty() && i == 0 => continue,
            _ => {
                return Err(FisheyeError::BadCsvLine {
                    line: i + 1,
                    text: line.to_string(),
                })
            }
        }
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_with_header_comments_and_separators() {
        let v =
            parse_angle_radius_csv("angle_deg,radius_px\n# box\n0,0\n30; 101.5\n\n60\t200 # x\n")
                .unwrap();
        assert_eq!(v.len(), 3);
        assert_eq!((v[1].angle_deg, v[1].radius_px), (30.0, 101.5));
        assert_eq!((v[2].angle_deg, v[2].radius_px), (60.0, 200.0));
    }

    #[test]
    fn csv_bad_line_names_its_number() {
        let e = parse_angle_radius_csv("0,0\n30,100,7\n").unwrap_err();
        assert!(matches!(e, FisheyeError::BadCsvLine { line: 2, .. }), "{e}");
        assert!(parse_angle_radius_csv("x,y\nfoo,bar\n").is_err());
    }
}
