//! Marks drawn on an 8-bit preview of the sky: the lens's visible circle, the 180° horizon, the
//! north point and the sun (like the seed's Fig. 7).
//!
//! Pure pixel drawing on [`RgbImage<u8>`] (origin top-left, `x` right, `y` down, pixel centres
//! at `+0.5`; positions in the same continuous coordinates as [`crate::sky`] uses). Circles are
//! anti-aliased by coverage: each pixel near the curve is blended with the line colour in
//! proportion to how much of a `width`-pixel band around the circle covers its centre, so the
//! rings look the same at any radius and sub-pixel centres show. Colours: visible circle grey,
//! horizon white, north a filled blue disc with a white rim, sun a yellow ring.

use std::ops::Range;

use crate::image::{Circle, PixelPoint, RgbImage};

/// What to draw; `None` fields are skipped.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OverlayMarks {
    /// The lens's visible image circle (thin grey line).
    pub visible: Option<Circle>,
    /// The 180° horizon circle (thin white line).
    pub horizon: Option<Circle>,
    /// The north point on the horizon (blue disc).
    pub north: Option<PixelPoint>,
    /// The sun (yellow ring).
    pub sun: Option<PixelPoint>,
}

/// Visible-circle colour.
pub const VISIBLE_COLOUR: [u8; 3] = [160, 160, 160];
/// Horizon colour.
pub const HORIZON_COLOUR: [u8; 3] = [255, 255, 255];
/// North-marker colour.
pub const NORTH_COLOUR: [u8; 3] = [30, 90, 255];
/// Sun-ring colour.
pub const SUN_COLOUR: [u8; 3] = [255, 220, 0];

/// Draws `marks` on `img`. Marker sizes scale with the image (about 1 % of its smaller side,
/// at least 3 px), so previews of any size read the same. Non-finite positions are skipped.
pub fn draw_overlay(img: &mut RgbImage<u8>, marks: &OverlayMarks) {
    let scale = (img.width.min(img.height) as f64 / 100.0).max(3.0);
    let line = (scale / 3.0).max(1.0);
    if let Some(c) = marks.visible {
        draw_ring(img, c.cx, c.cy, c.r, line, VISIBLE_COLOUR);
    }
    if let Some(c) = marks.horizon {
        draw_ring(img, c.cx, c.cy, c.r, line, HORIZON_COLOUR);
    }
    if let Some(p) = marks.north {
        draw_disc(img, p.x, p.y, scale + line, HORIZON_COLOUR);
        draw_disc(img, p.x, p.y, scale, NORTH_COLOUR);
    }
    if let Some(p) = marks.sun {
        draw_ring(img, p.x, p.y, 2.0 * scale, 1.5 * line, SUN_COLOUR);
    }
}

fn blend(img: &mut RgbImage<u8>, x: usize, y: usize, colour: [u8; 3], alpha: f64) {
    if alpha <= 0.0 {
        return;
    }
    let a = alpha.min(1.0);
    let p = img.pixel(x, y);
    let mix = |o: u8, n: u8| (f64::from(o) * (1.0 - a) + f64::from(n) * a).round() as u8;
    img.set_pixel(
        x,
        y,
        [
            mix(p[0], colour[0]),
            mix(p[1], colour[1]),
            mix(p[2], colour[2]),
        ],
    );
}

/// The pixels of `img` within `ext` pixels of `(cx, cy)`, one pixel of margin added.
fn around(img: &RgbImage<u8>, cx: f64, cy: f64, ext: f64) -> (Range<usize>, Range<usize>) {
    let r = ext + 1.0;
    Circle { cx, cy, r }.pixel_bounds(img.width, img.height)
}

/// A ring of radius `r` and line width `width` (pixels) with a one-pixel coverage ramp.
pub fn draw_ring(img: &mut RgbImage<u8>, cx: f64, cy: f64, r: f64, width: f64, colour: [u8; 3]) {
    if !(cx.is_finite() && cy.is_finite() && r.is_finite() && r >= 0.0 && width > 0.0) {
        return;
    }
    let half = 0.5 * width;
    let (xs, ys) = around(img, cx, cy, r + half + 1.0);
    for y in ys {
        let dy = y as f64 + 0.5 - cy;
        for x in xs.clone() {
            let dx = x as f64 + 0.5 - cx;
            let d = ((dx * dx + dy * dy).sqrt() - r).abs();
            blend(img, x, y, colour, half + 0.5 - d);
        }
    }
}

/// A filled disc of radius `r` pixels with a one-pixel coverage ramp at its edge.
pub fn draw_disc(img: &mut RgbImage<u8>, cx: f64, cy: f64, r: f64, colour: [u8; 3]) {
    if !(Circle { cx, cy, r }).is_valid() {
        return;
    }
    let (xs, ys) = around(img, cx, cy, r + 1.0);
    for y in ys {
        let dy = y as f64 + 0.5 - cy;
        for x in xs.clone() {
            let dx = x as f64 + 0.5 - cx;
            blend(img, x, y, colour, r + 0.5 - (dx * dx + dy * dy).sqrt());
        }
    }
}

/// A tone-mapped picture of `image` (with `tm`) with `marks` drawn on it.
pub fn overlay_picture(
    image: &crate::image::HdrImage,
    marks: &OverlayMarks,
    tm: &crate::tonemap::ToneMap,
) -> Result<RgbImage<u8>, crate::tonemap::TonemapError> {
    let mut rgb = crate::tonemap::tonemap_u8(image, tm)?;
    draw_overlay(&mut rgb, marks);
    Ok(rgb)
}
