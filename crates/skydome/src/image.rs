//! Plain pixel buffers shared by every stage.
//!
//! Conventions, decided here once for the whole crate:
//! - pixel origin is the **top-left** corner, `x` grows to the right, `y` grows downwards;
//! - APIs take coordinates in `(x, y)` order and sizes as `(width, height)`;
//! - pixel `(x, y)` covers the square `[x, x+1) × [y, y+1)`, so its centre is `(x + 0.5, y + 0.5)`;
//! - colour is interleaved RGB, row-major: the red value of `(x, y)` is `data[3 * (y * width + x)]`.

use std::ops::Range;

/// An interleaved RGB image (`3 * width * height` samples, row-major, origin top-left).
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage<T> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Interleaved samples `R, G, B, R, G, B, …`; length `3 * width * height`.
    pub data: Vec<T>,
}

/// A linear floating-point radiance map (relative units unless a calibration says otherwise).
pub type HdrImage = RgbImage<f32>;

impl<T: Copy + Default> RgbImage<T> {
    /// An image of the given size filled with `T::default()` (zero for numbers).
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            data: vec![T::default(); 3 * width * height],
        }
    }
}

impl<T: Copy> RgbImage<T> {
    /// Wraps an interleaved buffer; returns `None` when `data.len() != 3 * width * height`.
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> Option<Self> {
        (width.checked_mul(height)?.checked_mul(3)? == data.len()).then_some(Self {
            width,
            height,
            data,
        })
    }

    /// Wraps an interleaved buffer, or says why it does not fit (`3 * width * height`
    /// samples).
    pub fn try_from_vec(
        width: usize,
        height: usize,
        data: Vec<T>,
    ) -> Result<Self, BufferSizeError> {
        check_samples(data.len(), width, height, 3)?;
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Checks that the buffer holds `3 * width * height` samples (the fields are public, so an
    /// image built field by field may not).
    pub fn validate(&self) -> Result<(), BufferSizeError> {
        check_samples(self.data.len(), self.width, self.height, 3)
    }

    /// Number of pixels (`width * height`).
    pub fn pixel_count(&self) -> usize {
        self.width * self.height
    }

    /// The RGB triple at `(x, y)`; panics when out of bounds (callers iterate within the size).
    #[inline]
    pub fn pixel(&self, x: usize, y: usize) -> [T; 3] {
        let i = 3 * (y * self.width + x);
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Sets the RGB triple at `(x, y)`; panics when out of bounds.
    #[inline]
    pub fn set_pixel(&mut self, x: usize, y: usize, v: [T; 3]) {
        let i = 3 * (y * self.width + x);
        self.data[i..i + 3].copy_from_slice(&v);
    }

    /// Iterates over RGB triples in row-major order.
    pub fn pixels(&self) -> impl Iterator<Item = [T; 3]> + '_ {
        self.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]])
    }
}

/// Rec. 709 / sRGB relative luminance of a linear RGB triple.
#[inline]
pub fn luminance(rgb: [f32; 3]) -> f32 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// Radiance's luminous efficacy of its RGB "watts", lm/W: its tools (`pvalue -o`, `evalglare`,
/// `falsecolor`) take luminance = 179 × (0.265 R + 0.670 G + 0.065 B).
pub const RADIANCE_EFFICACY: f64 = 179.0;

/// Luminance (or illuminance, from irradiance) of a linear RGB radiance the way Radiance's tools
/// compute it: `179 × (0.265 R + 0.670 G + 0.065 B)`; cd/m² (or lux) when the radiance is in
/// Radiance's W·sr⁻¹·m⁻², in relative units otherwise. (Radiance's primaries, not the Rec. 709
/// weights of [`luminance`], which is for display.)
pub fn radiance_luminance(rgb: [f64; 3]) -> f64 {
    RADIANCE_EFFICACY * (0.265 * rgb[0] + 0.670 * rgb[1] + 0.065 * rgb[2])
}

/// Bilinear interpolation at a continuous pixel position (centres at `+0.5`, edges clamped: a
/// position beyond the border takes the border's value): the four neighbours and their weights.
/// The one sampler of the crate ([`RgbImage::bilinear`], the lens-circle detector's profiles).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bilinear {
    /// Pixel indices `y * width + x` of the top-left, top-right, bottom-left and bottom-right
    /// neighbours.
    pub idx: [usize; 4],
    /// Weight of the right column, `0..=1`.
    pub ax: f32,
    /// Weight of the bottom row, `0..=1`.
    pub ay: f32,
}

impl Bilinear {
    /// The neighbours of `(x, y)` in a `width × height` image (both at least 1).
    #[inline]
    pub fn at(width: usize, height: usize, x: f64, y: f64) -> Self {
        let fx = (x - 0.5).clamp(0.0, (width - 1) as f64);
        let fy = (y - 0.5).clamp(0.0, (height - 1) as f64);
        // Non-negative, so truncation is the floor (without a libm call).
        let x0 = fx as usize;
        let y0 = fy as usize;
        let x1 = (x0 + 1).min(width - 1);
        let y1 = (y0 + 1).min(height - 1);
        Self {
            idx: [
                y0 * width + x0,
                y0 * width + x1,
                y1 * width + x0,
                y1 * width + x1,
            ],
            ax: (fx - x0 as f64) as f32,
            ay: (fy - y0 as f64) as f32,
        }
    }

    /// The interpolated value from the four neighbours' values (in [`Bilinear::idx`] order),
    /// as `a + (b − a)·t` steps.
    #[inline]
    pub fn mix(&self, [v00, v01, v10, v11]: [f32; 4]) -> f32 {
        let top = v00 + (v01 - v00) * self.ax;
        let bot = v10 + (v11 - v10) * self.ax;
        top + (bot - top) * self.ay
    }

    /// The same value as [`Bilinear::mix`] written as the weighted sum `a·(1 − t) + b·t`,
    /// which rounds differently in the last bit: the lens-circle detector's form, kept so that
    /// detected circles (and every output that depends on them) stay bit for bit the same.
    #[inline]
    pub fn weighted_sum(&self, [v00, v01, v10, v11]: [f32; 4]) -> f32 {
        let (ax, ay) = (self.ax, self.ay);
        let top = v00 * (1.0 - ax) + v01 * ax;
        let bot = v10 * (1.0 - ax) + v11 * ax;
        top * (1.0 - ay) + bot * ay
    }
}

impl HdrImage {
    /// Bilinear sample at the continuous position `(x, y)` (pixel centres at `+0.5`, edges
    /// clamped). The image must not be empty.
    #[inline]
    pub fn bilinear(&self, x: f64, y: f64) -> [f32; 3] {
        let b = Bilinear::at(self.width, self.height, x, y);
        let d = &self.data;
        let [i00, i01, i10, i11] = b.idx.map(|i| 3 * i);
        std::array::from_fn(|c| b.mix([d[i00 + c], d[i01 + c], d[i10 + c], d[i11 + c]]))
    }
}

/// A circle in pixel coordinates (same conventions as above): centre `(cx, cy)` and radius `r`,
/// all in pixels. Used for the fish-eye lens's visible image circle and for the 180° horizon.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Circle {
    /// Centre column in pixels (pixel centres at `x + 0.5`).
    pub cx: f64,
    /// Centre row in pixels (pixel centres at `y + 0.5`).
    pub cy: f64,
    /// Radius in pixels.
    pub r: f64,
}

impl Circle {
    /// True when the centre is finite and the radius finite and positive.
    pub fn is_valid(&self) -> bool {
        self.cx.is_finite() && self.cy.is_finite() && self.r.is_finite() && self.r > 0.0
    }

    /// The pixels of a `width × height` image that the circle's bounding square
    /// `[cx − r, cx + r] × [cy − r, cy + r]` touches: the columns and the rows, each clipped
    /// to the image (an empty range when the circle lies beside the image or is not finite).
    pub fn pixel_bounds(&self, width: usize, height: usize) -> (Range<usize>, Range<usize>) {
        let span = |c: f64, n: usize| {
            let lo = (c - self.r).floor().max(0.0) as usize;
            let hi = ((c + self.r).ceil().max(0.0) as usize).min(n);
            lo..hi
        };
        (span(self.cx, width), span(self.cy, height))
    }

    /// True when the centre of pixel `(x, y)` lies inside the circle.
    #[inline]
    pub fn contains_pixel(&self, x: usize, y: usize) -> bool {
        let dx = x as f64 + 0.5 - self.cx;
        let dy = y as f64 + 0.5 - self.cy;
        dx * dx + dy * dy <= self.r * self.r
    }

    /// The pixels of row `y` whose centres are inside the circle, as the span `x0..x1` of an
    /// image `width` pixels wide (empty when none are): the pixels for which
    /// [`Circle::contains_pixel`] holds, without testing each (the circle is convex).
    pub fn row_span(&self, y: usize, width: usize) -> (usize, usize) {
        let dy = y as f64 + 0.5 - self.cy;
        let h2 = self.r * self.r - dy * dy;
        if h2.is_nan() || h2 < 0.0 {
            return (0, 0);
        }
        let h = h2.sqrt();
        // Centres x + 0.5 within [cx − h, cx + h], then the exact test at both ends (the square
        // root can round either way).
        let x0 = (self.cx - h - 0.5).ceil().clamp(0.0, width as f64) as usize;
        let x1 = ((self.cx + h - 0.5).floor() + 1.0).clamp(0.0, width as f64) as usize;
        let (mut x0, mut x1) = (x0, x1.max(x0));
        while x0 > 0 && self.contains_pixel(x0 - 1, y) {
            x0 -= 1;
        }
        while x0 < x1 && !self.contains_pixel(x0, y) {
            x0 += 1;
        }
        while x1 < width && self.contains_pixel(x1, y) {
            x1 += 1;
        }
        while x1 > x0 && !self.contains_pixel(x1 - 1, y) {
            x1 -= 1;
        }
        (x0, x1)
    }
}

/// A pixel position (origin top-left, `x` right, `y` down, pixel centres at `+0.5`), in
/// continuous pixel units.
///
/// Its one text form is the seed's `-Y y +X x` (as in Radiance's resolution line), written in
/// the `#SUN=` / `#NORTH=` header lines and the EXR `skydome:sun` / `skydome:north` attributes:
/// `Display` writes it, `FromStr` reads it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PixelPoint {
    /// Column in pixels from the left edge.
    pub x: f64,
    /// Row in pixels from the top edge.
    pub y: f64,
}

impl std::fmt::Display for PixelPoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "-Y {} +X {}", fmt_num(self.y), fmt_num(self.x))
    }
}

/// A text that is not `-Y y +X x` with finite numbers.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{0}' is not a pixel position; expected '-Y <row> +X <column>'")]
pub struct BadPixelPoint(pub String);

impl std::str::FromStr for PixelPoint {
    type Err = BadPixelPoint;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || BadPixelPoint(s.to_string());
        let t: Vec<&str> = s.split_whitespace().collect();
        let ["-Y", y, "+X", x] = t.as_slice() else {
            return Err(bad());
        };
        let (x, y) = (
            x.parse::<f64>().map_err(|_| bad())?,
            y.parse::<f64>().map_err(|_| bad())?,
        );
        match x.is_finite() && y.is_finite() {
            true => Ok(PixelPoint { x, y }),
            false => Err(bad()),
        }
    }
}

/// A number for a text header: plain decimal from 1e-5 to 1e16 (and 0), scientific otherwise;
/// the shortest text that reads back to the same `f64`.
pub(crate) fn fmt_num(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || (1e-5..1e16).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// A sample buffer whose length does not match its stated size.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("buffer holds {got} samples but {width}x{height} needs {expected}: pass a buffer of the stated size")]
pub struct BufferSizeError {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Samples expected.
    pub expected: usize,
    /// Samples given.
    pub got: usize,
}

/// Checks that a buffer of `len` samples holds `channels` samples for each of
/// `width × height` pixels.
pub fn check_samples(
    len: usize,
    width: usize,
    height: usize,
    channels: usize,
) -> Result<(), BufferSizeError> {
    let expected = width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(channels))
        .unwrap_or(usize::MAX);
    match len == expected {
        true => Ok(()),
        false => Err(BufferSizeError {
            width,
            height,
            expected,
            got: len,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_span_is_the_run_of_pixels_contains_pixel_accepts() {
        // Centres on and off pixel corners and centres, radii from under a pixel up, circles
        // cut by every edge and lying outside the image.
        let circles = [
            Circle {
                cx: 20.0,
                cy: 15.0,
                r: 10.0,
            },
            Circle {
                cx: 20.5,
                cy: 15.5,
                r: 7.5,
            },
            Circle {
                cx: 0.3,
                cy: 29.9,
                r: 12.25,
            },
            Circle {
                cx: 39.7,
                cy: -2.0,
                r: 6.0,
            },
            Circle {
                cx: 10.5,
                cy: 10.5,
                r: 0.5,
            },
            Circle {
                cx: 10.5,
                cy: 10.5,
                r: 0.49,
            },
            Circle {
                cx: 60.0,
                cy: 15.0,
                r: 5.0,
            },
            Circle {
                cx: 20.0,
                cy: 15.0,
                r: 1000.0,
            },
        ];
        let (w, h) = (40usize, 30usize);
        for c in &circles {
            for y in 0..h + 3 {
                let (x0, x1) = c.row_span(y, w);
                assert!(x0 <= x1 && x1 <= w, "{c:?} row {y}: {x0}..{x1}");
                for x in 0..w {
                    assert_eq!(
                        (x0..x1).contains(&x),
                        c.contains_pixel(x, y),
                        "{c:?} ({x},{y})"
                    );
                }
            }
        }
    }
}
