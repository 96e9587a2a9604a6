//! Cropping a fish-eye image to the dome `θ ≤ fov/2`.

use super::{check_fov, FisheyeError, LensProfile};
use crate::image::{Circle, HdrImage};

/// The result of [`crop_dome`].
#[derive(Debug, Clone, PartialEq)]
pub struct DomeCrop {
    /// Square image in the source's projection and resolution; pixels beyond the crop circle
    /// (and outside the source frame) are zero.
    pub image: HdrImage,
    /// The crop circle (the horizon for 180°) in output pixel coordinates. Its centre is within
    /// half a pixel of the image centre (the copy is pixel-exact, so it is not resampled to sit
    /// exactly in the middle).
    pub horizon: Circle,
    /// Source pixel column of output column 0 (may be negative when the crop pokes out).
    pub offset_x: i64,
    /// Source pixel row of output row 0.
    pub offset_y: i64,
    /// Crop radius in source pixels: `r(fov_out/2)`.
    pub crop_radius_px: f64,
}

/// Crops a fish-eye image to the dome `θ ≤ fov_out_deg/2` around the lens's optical axis
/// (`fov_out_deg = 180` gives the sky-dome whose circle is the horizon), keeping the lens's
/// projection; everything beyond is set to zero. Errors when the lens cannot image that angle
/// or the crop would exceed 32768 pixels a side.
pub fn crop_dome(
    img: &HdrImage,
    lens: &LensProfile,
    fov_out_deg: f64,
) -> Result<DomeCrop, FisheyeError> {
    crop_dome_from(img, (0, 0), lens, fov_out_deg)
}

/// The square [`crop_dome`] copies, in source pixels: its top-left pixel `(x, y)` (negative
/// when the crop pokes out of the frame), its side and the crop radius `r(fov_out/2)`.
pub fn dome_crop_box(
    lens: &LensProfile,
    fov_out_deg: f64,
) -> Result<(i64, i64, usize, f64), FisheyeError> {
    lens.validate()?;
    check_fov(fov_out_deg)?;
    let r = lens.radius_at_deg(0.5 * fov_out_deg)?;
    let half = (r + 0.5).ceil();
    if !(half.is_finite() && half <= 16384.0) {
        return Err(FisheyeError::BadParameter {
            what: "crop radius (px)",
            value: r,
            hint: "the crop would exceed 32768 px a side: check the lens profile",
        });
    }
    let ox = (lens.circle.cx - half).round() as i64;
    let oy = (lens.circle.cy - half).round() as i64;
    Ok((ox, oy, 2 * half as usize, r))
}

/// As [`crop_dome`], for `img` a part of the source frame whose pixel (0, 0) is the source's
/// pixel `origin` (x, y) — e.g. the square of [`dome_crop_box`] alone, all a crop reads. The
/// result is the same as cropping the whole frame: `lens` and the offsets stay in the whole
/// frame's pixels.
pub fn crop_dome_from(
    img: &HdrImage,
    origin: (i64, i64),
    lens: &LensProfile,
    fov_out_deg: f64,
) -> Result<DomeCrop, FisheyeError> {
    let (ox, oy, n, r) = dome_crop_box(lens, fov_out_deg)?;
    let horizon = Circle {
        cx: lens.circle.cx - ox as f64,
        cy: lens.circle.cy - oy as f64,
        r,
    };
    let mut out = HdrImage::new(n, n);
    let r2 = r * r;
    let copy_row = |(y, row): (usize, &mut [f32])| {
        let sy = oy + y as i64 - origin.1;
        if sy < 0 || sy >= img.height as i64 {
            return;
        }
        let dy = y as f64 + 0.5 - horizon.cy;
        let src_row = &img.data[3 * sy as usize * img.width..3 * (sy as usize + 1) * img.width];
        for x in 0..n {
            let sx = ox + x as i64 - origin.0;
            let dx = x as f64 + 0.5 - horizon.cx;
            if sx < 0 || sx >= img.width as i64 || dx * dx + dy * dy > r2 {
                continue;
            }
            let s = 3 * sx as usize;
            row[3 * x..3 * x + 3].copy_from_slice(&src_row[s..s + 3]);
        }
    };
    // Rows in parallel with the `parallel` feature.
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        out.data
            .par_chunks_exact_mut(3 * n.max(1))
            .enumerate()
            .for_each(copy_row);
    }
    #[cfg(not(feature = "parallel"))]
    out.data
        .chunks_exact_mut(3 * n.max(1))
        .enumerate()
        .for_each(copy_row);
    Ok(DomeCrop {
        image: out,
        horizon,
        offset_x: ox,
        offset_y: oy,
        crop_radius_px: r,
    })
}
