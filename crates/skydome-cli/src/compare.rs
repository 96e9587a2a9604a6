//! `skydome compare A B`: how far apart two radiance maps are, after fitting one global scale.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use skydome::compare::{self, CompareOptions};

/// Arguments of `skydome compare`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The radiance map under test (.hdr or .exr).
    pub a: PathBuf,
    /// The reference radiance map (.hdr or .exr).
    pub b: PathBuf,
    /// Compare only inside this circle (CX,CY,R in pixels).
    #[arg(long, value_parser = crate::calibrate::parse_circle, value_name = "CX,CY,R")]
    pub circle: Option<skydome::image::Circle>,
    /// Fit one scale per channel instead of one for all three.
    #[arg(long)]
    pub per_channel: bool,
    /// A's standard-error map (`skydome merge --confidence se.exr`): also report its median
    /// and the error in units of it (0.674 when the stated error is honest).
    #[arg(long, value_name = "SE.exr")]
    pub sigma: Option<PathBuf>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// The top-level entry point for `skydome compare`.
pub fn run(a: Args) -> Result<()> {
    let ra = crate::radiance::read(&a.a)?;
    let rb = crate::radiance::read(&a.b)?;
    let (ia, ib) = (&ra.image, &rb.image);
    if (ia.width, ia.height) != (ib.width, ib.height) {
        bail!(
            "{}: size {}x{} differs from {} ({}x{})",
            a.b.display(),
            ib.width,
            ib.height,
            a.a.display(),
            ia.width,
            ia.height
        );
    }
    let mask: Option<Vec<bool>> = a.circle.map(|c| {
        (0..ia.pixel_count())
            .map(|p| c.contains_pixel(p % ia.width, p / ia.width))
            .collect()
    });
    let mut r = compare::compare(
        ia,
        ib,
        mask.as_deref(),
        &CompareOptions {
            per_channel_scale: a.per_channel,
        },
    )
    .with_context(|| format!("{} vs {}", a.a.display(), a.b.display()))?;
    if let Some(p) = &a.sigma {
        let se = crate::radiance::read(p)?;
        compare::with_standard_error(&mut r, ia, ib, &se.image, mask.as_deref())
            .with_context(|| format!("{}", p.display()))?;
    }
    if a.json {
        crate::out(&serde_json::to_string_pretty(&r)?);
    } else {
        crate::out(&format!(
            "{} vs {} over {} pixels\nscale            {:.6} {:.6} {:.6}\nnormalised std   {:.5} (seed eq. 5)\nseed's rho       {:.5} (std of min-max tone-mapped difference, seed 9.1)\nmedian rel error {:.3} %\np95 rel error    {:.3} %\nlog2 RMSE        {:.4} stops",
            a.a.display(),
            a.b.display(),
            r.pixels,
            r.scale[0],
            r.scale[1],
            r.scale[2],
            r.normalised_std,
            r.tonemapped_std,
            100.0 * r.median_rel_error,
            100.0 * r.p95_rel_error,
            r.log2_rmse
        ));
        if let (Some(s), Some(z)) = (r.median_standard_error_stops, r.median_error_in_sigmas) {
            crate::out(&format!(
                "stated std error {s:.4} stops (median)\nerror / std error {z:.3} (median; 0.674 if the stated error is honest)"
            ));
        }
    }
    Ok(())
}
