//! Pictures for judging a capture: camera response curves, a false-colour luminance map with a
//! colour bar, and a histogram of log luminance. Everything returns encoded bytes (PNG, SVG) or
//! an [`RgbImage<u8>`]; nothing touches the filesystem.
//!
//! # Response curves
//! Drawn in the style of Debevec & Malik (SIGGRAPH 1997, Fig. 2 and 3): **x = log exposure
//! `ln(E·Δt)`, y = pixel value `Z` (0–255)**, one solid line per channel `g_c(Z)` in red, green
//! and blue, with the solver's sample points `(ln E_i + ln Δt_j, Z_ij)` as small translucent dots
//! behind them. White background, boxed axes, light grid, legend — a figure that can go into a
//! paper as-is. [`response_curves_svg`] is the vector version of [`response_curves_png`].
//!
//! # False colour
//! [`false_colour`] maps log₁₀ luminance linearly onto a colour ramp (dark blue → blue → cyan →
//! green → yellow → orange → red → white) between two bounds — by default the 1st and 99.9th
//! percentiles rounded out to whole or half decades — and appends a labelled vertical colour bar.
//! Luminance is relative unless [`FalseColour::scale`] converts it to cd/m² (`L_abs = scale ·
//! L`), as Radiance's `falsecolor -s`/`-m` would. Masked and zero pixels stay black.
//!
//! # Histogram
//! [`log_luminance_histogram_png`] bins log₂ luminance at ¼ stop and prints the dynamic range in
//! stops twice: min→max over all positive pixels, and between the 0.1st and 99.9th percentiles,
//! which ignores a handful of hot or dead pixels.
//!
//! # Fonts
//! DejaVu Sans (Bitstream Vera licence, `assets/DejaVuSans-LICENSE.txt`) is embedded with
//! `include_bytes!`. Text is laid out and rasterised with `ab_glyph` inside a thin wrapper
//! around the plotters backend instead of plotters' own font lookup: plotters has no font
//! engine on `wasm32-unknown-unknown` (it asks the browser DOM), and this crate must draw the
//! same pictures there. On native targets the font is also registered with plotters'
//! `register_font`, so any plotters element that bypasses the backend still finds it.

use std::sync::OnceLock;

use ab_glyph::{Font, FontRef, PxScale, ScaleFont};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, VPos};
use plotters_backend::{BackendColor, BackendCoord, BackendTextStyle, DrawingErrorKind};

use crate::formats::picture::{self, PictureFormat};
use crate::image::{luminance, Circle, HdrImage, RgbImage};
use crate::tonemap::{self, TonemapError};

/// DejaVu Sans 2.37 (Debian `fonts-dejavu-core`), Bitstream Vera licence.
pub static FONT_TTF: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// The family name the embedded font is registered under.
pub const FONT_FAMILY: &str = "DejaVu Sans";

/// Errors while drawing or encoding a picture.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// A figure size too small to draw in or absurdly large.
    #[error("figure size {width}×{height} px is out of range; use 200..=8000 px per side")]
    BadSize {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
    },
    /// Response curve input that cannot be plotted.
    #[error("response curve for channel {channel} has {len} values ({finite} finite); pass 256 finite g(Z) values per channel")]
    BadCurve {
        /// 0 = red, 1 = green, 2 = blue.
        channel: usize,
        /// Values given.
        len: usize,
        /// Finite values among them.
        finite: usize,
    },
    /// A parameter outside its range.
    #[error("{name} = {value} is out of range: {hint}")]
    BadParameter {
        /// Name of the parameter.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is accepted.
        hint: &'static str,
    },
    /// The image has nothing to measure.
    #[error("no pixel has positive luminance; nothing to plot — check the mask or the input file")]
    NoLight,
    /// From luminance statistics.
    #[error(transparent)]
    Tonemap(#[from] TonemapError),
    /// The embedded font could not be parsed (a build problem, not a user one).
    #[error(
        "the embedded font could not be loaded; rebuild skydome (assets/DejaVuSans.ttf is damaged)"
    )]
    Font,
    /// plotters failed while drawing.
    #[error("drawing failed: {0}")]
    Draw(String),
    /// PNG encoding failed.
    #[error("PNG encoding failed: {0}")]
    Encode(String),
}

fn draw_err<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError::Draw(format!("{e:?}"))
}

fn font() -> Result<&'static FontRef<'static>, PlotError> {
    static FONT: OnceLock<Option<FontRef<'static>>> = OnceLock::new();
    FONT.get_or_init(|| {
        #[cfg(not(target_arch = "wasm32"))]
        {
            // Best effort: our backend wrapper draws all text itself, so failure here is harmless.
            let _ = plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, FONT_TTF);
        }
        FontRef::try_from_slice(FONT_TTF).ok()
    })
    .as_ref()
    .ok_or(PlotError::Font)
}

fn check_size((w, h): (u32, u32)) -> Result<(), PlotError> {
    if !(200..=8000).contains(&w) || !(200..=8000).contains(&h) {
        return Err(PlotError::BadSize {
            width: w,
            height: h,
        });
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Backend wrapper with embedded-font text
// ---------------------------------------------------------------------------------------------

/// Wraps a plotters backend; lays out text with the embedded font and, for bitmaps, rasterises
/// it with anti-aliasing through `draw_pixel`. Vector primitives pass straight through, so SVG
/// output keeps real `<text>`, lines and circles.
struct EmbeddedFont<B> {
    inner: B,
    font: &'static FontRef<'static>,
    raster_text: bool,
}

/// Text geometry for one string at one size: the scaled font and the box size in pixels.
struct Layout {
    scale: PxScale,
    width: f32,
    ascent: f32,
    height: f32,
}

impl<B> EmbeddedFont<B> {
    fn layout(&self, text: &str, size: f64) -> Layout {
        // plotters' convention: a font "size" is 1.24 em (see its SVG backend's font-size).
        let em = (size / 1.24) as f32;
        let upem = self.font.units_per_em().unwrap_or(2048.0);
        let scale = PxScale::from(em * self.font.height_unscaled() / upem);
        let sf = self.font.as_scaled(scale);
        let mut width = 0.0;
        let mut prev = None;
        for c in text.chars() {
            let g = sf.glyph_id(c);
            if let Some(p) = prev {
                width += sf.kern(p, g);
            }
            width += sf.h_advance(g);
            prev = Some(g);
        }
        Layout {
            scale,
            width,
            ascent: sf.ascent(),
            height: sf.ascent() - sf.descent(),
        }
    }
}

impl<B: DrawingBackend> DrawingBackend for EmbeddedFont<B> {
    type ErrorType = B::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.inner.get_size()
    }
    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.ensure_prepared()
    }
    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.present()
    }
    fn draw_pixel(
        &mut self,
        p: BackendCoord,
        c: BackendColor,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_pixel(p, c)
    }
    fn draw_line<S: plotters_backend::BackendStyle>(
        &mut self,
        a: BackendCoord,
        b: BackendCoord,
        s: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_line(a, b, s)
    }
    fn draw_rect<S: plotters_backend::BackendStyle>(
        &mut self,
        a: BackendCoord,
        b: BackendCoord,
        s: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_rect(a, b, s, fill)
    }
    fn draw_path<S: plotters_backend::BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        s: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_path(path, s)
    }
    fn draw_circle<S: plotters_backend::BackendStyle>(
        &mut self,
        c: BackendCoord,
        r: u32,
        s: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_circle(c, r, s, fill)
    }
    fn fill_polygon<S: plotters_backend::BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        v: I,
        s: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.fill_polygon(v, s)
    }
    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        size: (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.blit_bitmap(pos, size, src)
    }

    fn estimate_text_size<S: BackendTextStyle>(
        &self,
        text: &str,
        style: &S,
    ) -> Result<(u32, u32), DrawingErrorKind<Self::ErrorType>> {
        let l = self.layout(text, style.size());
        Ok((l.width.ceil() as u32, l.height.ceil() as u32))
    }

    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        if !self.raster_text {
            return self.inner.draw_text(text, style, pos);
        }
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let l = self.layout(text, style.size());
        let dx = match style.anchor().h_pos {
            HPos::Left => 0.0,
            HPos::Center => -l.width / 2.0,
            HPos::Right => -l.width,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0.0,
            VPos::Center => -l.height / 2.0,
            VPos::Bottom => -l.height,
        };
        let trans = style.transform();
        let sf = self.font.as_scaled(l.scale);
        let mut pen = dx;
        let mut prev = None;
        for c in text.chars() {
            let id = sf.glyph_id(c);
            if let Some(p) = prev {
                pen += sf.kern(p, id);
            }
            prev = Some(id);
            let glyph = id.with_scale_and_position(l.scale, ab_glyph::point(pen, dy + l.ascent));
            pen += sf.h_advance(id);
            let Some(outline) = self.font.outline_glyph(glyph) else {
                continue;
            };
            let b = outline.px_bounds();
            let mut coverage = Vec::new();
            outline.draw(|x, y, a| coverage.push((x, y, a)));
            for (x, y, a) in coverage {
                if a <= 0.0 {
                    continue;
                }
                let lx = b.min.x as i32 + x as i32;
                let ly = b.min.y as i32 + y as i32;
                let (tx, ty) = trans.transform(lx, ly);
                self.inner.draw_pixel(
                    (pos.0 + tx, pos.1 + ty),
                    BackendColor {
                        alpha: color.alpha * a.min(1.0) as f64,
                        rgb: color.rgb,
                    },
                )?;
            }
        }
        Ok(())
    }
}

fn embedded<B: DrawingBackend>(inner: B, raster_text: bool) -> Result<EmbeddedFont<B>, PlotError> {
    Ok(EmbeddedFont {
        inner,
        font: font()?,
        raster_text,
    })
}

/// Encodes an 8-bit RGB image as PNG bytes (see [`crate::formats::picture`]).
pub fn encode_png_rgb8(img: &RgbImage<u8>) -> Result<Vec<u8>, PlotError> {
    picture::encode_rgb8(img, PictureFormat::Png).map_err(|e| PlotError::Encode(e.to_string()))
}

/// Encodes a 16-bit RGB image as PNG bytes (see [`crate::formats::picture`]).
pub fn encode_png_rgb16(img: &RgbImage<u16>) -> Result<Vec<u8>, PlotError> {
    picture::encode_rgb16(img, PictureFormat::Png).map_err(|e| PlotError::Encode(e.to_string()))
}

/// Draws onto a fresh white RGB bitmap with `f`, then encodes it as PNG.
fn render_png<F>(size: (u32, u32), f: F) -> Result<Vec<u8>, PlotError>
where
    F: FnOnce(&DrawingArea<EmbeddedFont<BitMapBackend<'_>>, Shift>) -> Result<(), PlotError>,
{
    check_size(size)?;
    let mut buf = vec![255u8; 3 * size.0 as usize * size.1 as usize];
    {
        let bm =
            BitMapBackend::<plotters::backend::RGBPixel>::with_buffer_and_format(&mut buf, size)
                .map_err(draw_err)?;
        let root = embedded(bm, true)?.into_drawing_area();
        f(&root)?;
        root.present().map_err(draw_err)?;
    }
    let img = RgbImage {
        width: size.0 as usize,
        height: size.1 as usize,
        data: buf,
    };
    encode_png_rgb8(&img)
}

// ---------------------------------------------------------------------------------------------
// Response curves
// ---------------------------------------------------------------------------------------------

const CHANNEL_COLOURS: [RGBColor; 3] = [
    RGBColor(200, 30, 30),
    RGBColor(20, 140, 40),
    RGBColor(30, 70, 210),
];
const CHANNEL_NAMES: [&str; 3] = ["red", "green", "blue"];

/// The x range shared by curves and samples, padded 3 % each side.
fn response_x_range(
    curves: &[Vec<f64>; 3],
    samples: [&[(f64, u8)]; 3],
) -> Result<(f64, f64), PlotError> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for (c, g) in curves.iter().enumerate() {
        let finite = g.iter().filter(|v| v.is_finite()).count();
        if g.len() != 256 || finite != 256 {
            return Err(PlotError::BadCurve {
                channel: c,
                len: g.len(),
                finite,
            });
        }
        for v in g {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    for s in samples {
        for (x, _) in s.iter().filter(|(x, _)| x.is_finite()) {
            lo = lo.min(*x);
            hi = hi.max(*x);
        }
    }
    let pad = ((hi - lo) * 0.03).max(0.05);
    Ok((lo - pad, hi + pad))
}

fn draw_response<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    curves: &[Vec<f64>; 3],
    samples: [&[(f64, u8)]; 3],
) -> Result<(), PlotError> {
    let (x0, x1) = response_x_range(curves, samples)?;
    let (w, _) = root.dim_in_pixel();
    let fs = (w as f64 / 40.0).clamp(12.0, 40.0);
    root.fill(&WHITE).map_err(draw_err)?;
    let mut chart = ChartBuilder::on(root)
        .caption(
            "Recovered response curves g(Z)",
            (FONT_FAMILY, fs * 1.25).into_font(),
        )
        .margin((fs * 0.8) as u32)
        .x_label_area_size((fs * 3.0) as u32)
        .y_label_area_size((fs * 3.6) as u32)
        .build_cartesian_2d(x0..x1, 0f64..255f64)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc("log exposure  ln(E·Δt)")
        .y_desc("pixel value  Z")
        .axis_desc_style((FONT_FAMILY, fs))
        .label_style((FONT_FAMILY, fs * 0.85))
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .y_labels(6)
        .x_labels(8)
        .y_label_formatter(&|v| format!("{v:.0}"))
        .x_label_formatter(&|v| format!("{v:.0}"))
        .draw()
        .map_err(draw_err)?;
    let dot = (w / 400).max(1);
    for (c, s) in samples.iter().enumerate() {
        let col = CHANNEL_COLOURS[c].mix(0.25).filled();
        chart
            .draw_series(
                s.iter()
                    .filter(|(x, _)| x.is_finite())
                    .map(|&(x, z)| plotters::element::Circle::new((x, z as f64), dot, col)),
            )
            .map_err(draw_err)?;
    }
    let stroke = (w / 300).max(2);
    for (c, g) in curves.iter().enumerate() {
        let col = CHANNEL_COLOURS[c];
        chart
            .draw_series(LineSeries::new(
                g.iter().enumerate().map(|(z, &x)| (x, z as f64)),
                col.stroke_width(stroke),
            ))
            .map_err(draw_err)?
            .label(CHANNEL_NAMES[c])
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(stroke))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font((FONT_FAMILY, fs * 0.9))
        .draw()
        .map_err(draw_err)?;
    Ok(())
}

/// Response curves as a PNG figure of `size = (width, height)` pixels (200..=8000 each).
///
/// `curves[c][z] = g_c(z) = ln(E·Δt)` for the pixel value `z` (256 finite values per channel,
/// red, green, blue); `samples[c]` are `(ln(E_i·Δt_j), Z_ij)` points used by the solver, drawn
/// as dots (non-finite `x` are skipped). Axes as in Debevec & Malik's Fig. 2: x = log exposure,
/// y = pixel value.
pub fn response_curves_png(
    curves: &[Vec<f64>; 3],
    samples: [&[(f64, u8)]; 3],
    size: (u32, u32),
) -> Result<Vec<u8>, PlotError> {
    render_png(size, |root| draw_response(root, curves, samples))
}

/// The same figure as [`response_curves_png`] as an SVG document (text stays text; fonts fall
/// back to the viewer's sans-serif when DejaVu Sans is not installed).
pub fn response_curves_svg(
    curves: &[Vec<f64>; 3],
    samples: [&[(f64, u8)]; 3],
    size: (u32, u32),
) -> Result<String, PlotError> {
    check_size(size)?;
    let mut out = String::new();
    {
        let root = embedded(SVGBackend::with_string(&mut out, size), false)?.into_drawing_area();
        draw_response(&root, curves, samples)?;
        root.present().map_err(draw_err)?;
    }
    Ok(out)
}

// ---------------------------------------------------------------------------------------------
// Histogram
// ---------------------------------------------------------------------------------------------

/// A histogram of log₂ luminance (¼-stop bins) over the pixels inside `mask`, with the dynamic
/// range in stops printed on it, as PNG bytes of `size` pixels.
pub fn log_luminance_histogram_png(
    img: &HdrImage,
    mask: Option<&Circle>,
    size: (u32, u32),
) -> Result<Vec<u8>, PlotError> {
    check_size(size)?;
    let stats = tonemap::luminance_stats(img, mask)?;
    if stats.count == 0 {
        return Err(PlotError::NoLight);
    }
    // Regroup the 1/32-stop statistics bins into ¼-stop bars.
    const GROUP: usize = 8;
    let fine = stats.log2_histogram();
    let bars: Vec<(f64, u64)> = fine
        .chunks(GROUP)
        .enumerate()
        .map(|(i, c)| (-64.0 + i as f64 * 0.25, c.iter().sum()))
        .filter(|(_, n)| *n > 0)
        .collect();
    let xmin = stats.min.log2().floor() - 0.5;
    let xmax = stats.max.log2().ceil() + 0.5;
    // Log counts: the sun is a few hundred pixels beside a few hundred thousand of sky, and must
    // still show as a bar.
    let ymax = bars.iter().map(|b| b.1).max().unwrap_or(1) as f64 * 3.0;
    let full = stats.dynamic_range_stops();
    let robust = stats.robust_range_stops(0.1, 99.9);
    render_png(size, |root| {
        let (w, _) = root.dim_in_pixel();
        let fs = (w as f64 / 40.0).clamp(12.0, 40.0);
        root.fill(&WHITE).map_err(draw_err)?;
        let mut chart = ChartBuilder::on(root)
            .caption("Luminance histogram", (FONT_FAMILY, fs * 1.25).into_font())
            .margin((fs * 0.8) as u32)
            .x_label_area_size((fs * 3.0) as u32)
            .y_label_area_size((fs * 4.2) as u32)
            .build_cartesian_2d(xmin..xmax, (0.7f64..ymax).log_scale())
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_label_formatter(&|v| format!("{v:.0}"))
            .x_desc("log₂ luminance (stops, relative)")
            .y_desc("pixels per ¼ stop (log scale)")
            .axis_desc_style((FONT_FAMILY, fs))
            .label_style((FONT_FAMILY, fs * 0.85))
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(215, 215, 215))
            .y_label_formatter(&|v| format_count(*v))
            .draw()
            .map_err(draw_err)?;
        let fill = RGBColor(70, 90, 140).filled();
        chart
            .draw_series(
                bars.iter()
                    .map(|&(x, n)| Rectangle::new([(x, 0.7), (x + 0.25, n as f64)], fill)),
            )
            .map_err(draw_err)?;
        let text = [
            format!("dynamic range {full:.1} stops (min → max)"),
            format!("{robust:.1} stops (0.1 % → 99.9 %)"),
            format!("{} pixels, {} zero", stats.count, stats.zero_count),
        ];
        let area = chart.plotting_area();
        let (px, py) = area.get_pixel_range();
        let style = TextStyle::from((FONT_FAMILY, fs * 0.95).into_font()).pos(
            plotters::style::text_anchor::Pos::new(HPos::Right, VPos::Top),
        );
        for (i, t) in text.iter().enumerate() {
            root.draw_text(
                t,
                &style,
                (
                    px.end - (fs * 0.6) as i32,
                    py.start + (fs * (0.5 + 1.3 * i as f64)) as i32,
                ),
            )
            .map_err(draw_err)?;
        }
        Ok(())
    })
}

fn format_count(v: f64) -> String {
    if v >= 1e6 {
        format!("{:.1}M", v / 1e6)
    } else if v >= 1e3 {
        format!("{:.0}k", v / 1e3)
    } else {
        format!("{v:.0}")
    }
}

// ---------------------------------------------------------------------------------------------
// False colour
// ---------------------------------------------------------------------------------------------

/// Settings for [`false_colour`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FalseColour {
    /// Pixels outside this circle are black and not measured.
    pub mask: Option<Circle>,
    /// Absolute calibration: cd/m² per relative unit. `None` labels the bar in relative units.
    pub scale: Option<f64>,
    /// Bar range `(low, high)` in the bar's units (relative or cd/m²), both > 0; `None` = the
    /// 1st–99.9th percentiles rounded outwards to half decades.
    pub range: Option<(f64, f64)>,
    /// Width of the colour-bar panel appended on the right, in pixels (0 = no bar).
    pub bar_width: usize,
}

impl Default for FalseColour {
    fn default() -> Self {
        Self {
            mask: None,
            scale: None,
            range: None,
            bar_width: 150,
        }
    }
}

/// Control points of the ramp, evenly spaced in log luminance. Hand-picked so neighbouring
/// decades differ in hue and the brightest end (the sun) reads as white.
const RAMP: [[f32; 3]; 8] = [
    [0.05, 0.02, 0.30],
    [0.10, 0.20, 0.85],
    [0.00, 0.65, 0.90],
    [0.15, 0.80, 0.25],
    [0.95, 0.92, 0.15],
    [1.00, 0.55, 0.05],
    [0.85, 0.05, 0.05],
    [1.00, 1.00, 1.00],
];

/// The false-colour ramp at `t ∈ [0, 1]` (clamped), as 8-bit sRGB.
pub fn false_colour_ramp(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) } as f32;
    let f = t * (RAMP.len() - 1) as f32;
    let i = (f as usize).min(RAMP.len() - 2);
    let u = f - i as f32;
    let mut o = [0u8; 3];
    for c in 0..3 {
        let v = RAMP[i][c] + (RAMP[i + 1][c] - RAMP[i][c]) * u;
        o[c] = (v * 255.0 + 0.5) as u8;
    }
    o
}

/// A false-colour map of log luminance with a labelled logarithmic colour bar on the right.
///
/// The map part keeps `img`'s size and pixel positions (the bar is appended, so the output is
/// `img.width + bar_width` wide, at least 300 px high — a shorter image is padded below with
/// black). Colour = `false_colour_ramp((log10 L − log10 lo) / (log10 hi − log10 lo))`.
pub fn false_colour(img: &HdrImage, opts: &FalseColour) -> Result<RgbImage<u8>, PlotError> {
    let stats = tonemap::luminance_stats(img, opts.mask.as_ref())?;
    let unit = opts.scale.unwrap_or(1.0);
    if !(unit > 0.0 && unit.is_finite()) {
        return Err(PlotError::BadParameter {
            name: "scale",
            value: unit,
            hint: "use a positive cd/m² per unit factor",
        });
    }
    if opts.bar_width > 2000 {
        return Err(PlotError::BadParameter {
            name: "bar width",
            value: opts.bar_width as f64,
            hint: "use 0..=2000 px",
        });
    }
    let (lo, hi) = match opts.range {
        Some((a, b)) => {
            if !(a > 0.0 && b > a && b.is_finite()) {
                return Err(PlotError::BadParameter {
                    name: "range",
                    value: a,
                    hint: "use 0 < low < high (in the bar's units)",
                });
            }
            (a, b)
        }
        None => {
            if stats.count == 0 {
                return Err(PlotError::NoLight);
            }
            let a = (stats.percentile(1.0) * unit).log10();
            let b = (stats.percentile(99.9) * unit).log10();
            let a = (a * 2.0).floor() / 2.0;
            let b = ((b * 2.0).ceil() / 2.0).max(a + 0.5);
            (10f64.powf(a), 10f64.powf(b))
        }
    };
    let (llo, lhi) = (lo.log10(), hi.log10());
    let bar = opts.bar_width;
    let out_w = img.width + bar;
    let out_h = img.height.max(if bar > 0 { 300 } else { 0 });
    let mut out = RgbImage::<u8>::new(out_w, out_h);
    let inv = 1.0 / (lhi - llo);
    for y in 0..img.height {
        let (x0, x1) = tonemap::row_span(opts.mask.as_ref(), img.width, y);
        let row = &img.data[3 * y * img.width..3 * (y + 1) * img.width];
        let orow = &mut out.data[3 * y * out_w..3 * y * out_w + 3 * img.width];
        for x in x0..x1 {
            let p = [row[3 * x], row[3 * x + 1], row[3 * x + 2]];
            let l = luminance([p[0].max(0.0), p[1].max(0.0), p[2].max(0.0)]) as f64;
            if l > 0.0 {
                let t = ((l * unit).log10() - llo) * inv;
                orow[3 * x..3 * x + 3].copy_from_slice(&false_colour_ramp(t));
            }
        }
    }
    if bar > 0 {
        draw_colour_bar(&mut out, img.width, lo, hi, opts.scale.is_some())?;
    }
    Ok(out)
}

fn draw_colour_bar(
    out: &mut RgbImage<u8>,
    x_start: usize,
    lo: f64,
    hi: f64,
    absolute: bool,
) -> Result<(), PlotError> {
    let (w, h) = (out.width as u32, out.height as u32);
    let bar_w = out.width - x_start;
    let fs = (bar_w as f64 / 8.0).clamp(11.0, 28.0);
    let margin_y = (fs * 2.5) as usize;
    let (y_top, y_bot) = (margin_y, out.height.saturating_sub((fs * 1.2) as usize));
    let x0 = x_start + (bar_w / 10).max(4);
    let x1 = x0 + (bar_w / 6).max(8);
    // The ramp itself, drawn directly: 1 px rows, top = high.
    for y in y_top..y_bot {
        let t = 1.0 - (y - y_top) as f64 / (y_bot - y_top - 1).max(1) as f64;
        let c = false_colour_ramp(t);
        for x in x0..x1.min(out.width) {
            out.set_pixel(x, y, c);
        }
    }
    let (llo, lhi) = (lo.log10(), hi.log10());
    let y_of = |v: f64| {
        y_top as f64 + (1.0 - (v.log10() - llo) / (lhi - llo)) * (y_bot - y_top - 1) as f64
    };
    let bm =
        BitMapBackend::<plotters::backend::RGBPixel>::with_buffer_and_format(&mut out.data, (w, h))
            .map_err(draw_err)?;
    let root = embedded(bm, true)?.into_drawing_area();
    let white = RGBColor(235, 235, 235);
    let style = TextStyle::from((FONT_FAMILY, fs).into_font())
        .color(&white)
        .pos(plotters::style::text_anchor::Pos::new(
            HPos::Left,
            VPos::Center,
        ));
    root.draw(&Rectangle::new(
        [(x0 as i32 - 1, y_top as i32 - 1), (x1 as i32, y_bot as i32)],
        white.stroke_width(1),
    ))
    .map_err(draw_err)?;
    // Ticks at every decade, plus 2× and 5× when the bar spans under three decades.
    let span = lhi - llo;
    let mults: &[f64] = if span < 3.01 {
        &[1.0, 2.0, 5.0]
    } else {
        &[1.0]
    };
    let mut d = llo.floor() as i32;
    while (d as f64) <= lhi.ceil() {
        for &m in mults {
            let v = m * 10f64.powi(d);
            if v < lo * 0.999 || v > hi * 1.001 {
                continue;
            }
            let y = y_of(v).round() as i32;
            let major = m == 1.0;
            let len = if major { 8 } else { 4 };
            root.draw(&PathElement::new(
                vec![(x1 as i32, y), (x1 as i32 + len, y)],
                white.stroke_width(1),
            ))
            .map_err(draw_err)?;
            root.draw_text(&format_tick(v), &style, (x1 as i32 + len + 4, y))
                .map_err(draw_err)?;
        }
        d += 1;
    }
    let title = TextStyle::from((FONT_FAMILY, fs).into_font())
        .color(&white)
        .pos(plotters::style::text_anchor::Pos::new(
            HPos::Left,
            VPos::Top,
        ));
    let label = if absolute {
        "L (cd/m²)"
    } else {
        "L (relative)"
    };
    root.draw_text(label, &title, (x0 as i32, (fs * 0.6) as i32))
        .map_err(draw_err)?;
    root.present().map_err(draw_err)?;
    Ok(())
}

/// Tick label for a value that is 1, 2 or 5 times a power of ten.
fn format_tick(v: f64) -> String {
    let e = v.log10().floor() as i32;
    if (-3..=5).contains(&e) {
        let decimals = (-e).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        let m = v / 10f64.powi(e);
        if (m - 1.0).abs() < 1e-6 {
            format!("1e{e}")
        } else {
            format!("{m:.0}e{e}")
        }
    }
}

// ---------------------------------------------------------------------------------------------
// A station's day
// ---------------------------------------------------------------------------------------------

/// What became of one capture, for [`day_png`] and [`day_svg`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DayState {
    /// Processed, the sun found.
    Ok,
    /// Processed, no sun found (clouds, or below the horizon): a hollow grey marker.
    SunHidden,
    /// The capture failed: a red cross along the bottom of both panels.
    Failed,
}

/// One capture on the day plot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DayPoint {
    /// Capture time in hours UTC from midnight of the first capture's day (may pass 24).
    pub hour_utc: f64,
    /// The dome's horizontal illuminance (lux when `absolute`, else relative units), when known.
    pub illuminance: Option<f64>,
    /// Sun elevation, degrees, when known.
    pub sun_elevation_deg: Option<f64>,
    /// What became of the capture.
    pub state: DayState,
}

/// A station's day as a PNG of `size` pixels (200..=8000 each): horizontal illuminance (log
/// scale) above and sun elevation below, both against time of day in UTC; failed captures are
/// red crosses at the bottom of both panels and captures without a sun hollow grey circles.
/// `absolute` labels the illuminance in lux. Points without a value are left out of a panel.
pub fn day_png(
    points: &[DayPoint],
    absolute: bool,
    size: (u32, u32),
) -> Result<Vec<u8>, PlotError> {
    render_png(size, |root| draw_day(root, points, absolute))
}

/// The same figure as [`day_png`] as an SVG document.
pub fn day_svg(points: &[DayPoint], absolute: bool, size: (u32, u32)) -> Result<String, PlotError> {
    check_size(size)?;
    let mut out = String::new();
    {
        let root = embedded(SVGBackend::with_string(&mut out, size), false)?.into_drawing_area();
        draw_day(&root, points, absolute)?;
        root.present().map_err(draw_err)?;
    }
    Ok(out)
}

fn draw_day<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    points: &[DayPoint],
    absolute: bool,
) -> Result<(), PlotError> {
    let hours: Vec<f64> = points
        .iter()
        .map(|p| p.hour_utc)
        .filter(|h| h.is_finite())
        .collect();
    let (mut h0, mut h1) = hours
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
            (a.min(h), b.max(h))
        });
    if !h0.is_finite() {
        (h0, h1) = (0.0, 24.0);
    }
    let pad = ((h1 - h0) * 0.03).max(0.25);
    let (x0, x1) = ((h0 - pad).floor().max(h0 - pad), h1 + pad);
    let lux: Vec<f64> = points
        .iter()
        .filter_map(|p| p.illuminance)
        .filter(|e| e.is_finite() && *e > 0.0)
        .collect();
    let (lo, hi) = lux
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &e| {
            (a.min(e), b.max(e))
        });
    let (y0, y1) = if lo.is_finite() {
        (lo / 2.0, hi * 2.0)
    } else {
        (0.1, 10.0)
    };
    let (w, h) = root.dim_in_pixel();
    let fs = (w as f64 / 50.0).clamp(12.0, 32.0);
    root.fill(&WHITE).map_err(draw_err)?;
    let failed = points
        .iter()
        .filter(|p| p.state == DayState::Failed)
        .count();
    let hidden = points
        .iter()
        .filter(|p| p.state == DayState::SunHidden)
        .count();
    let title = format!(
        "{} captures: {} ok, {} without a sun, {} failed",
        points.len(),
        points.len() - failed - hidden,
        hidden,
        failed
    );
    let (top, bottom) = root
        .titled(&title, (FONT_FAMILY, fs * 1.15))
        .map_err(draw_err)?
        .split_vertically((h as f64 * 0.55) as u32);
    let red = RGBColor(200, 30, 30);
    let grey = RGBColor(130, 130, 130);
    let ink = RGBColor(30, 70, 210);
    let cross = |x: f64, y: f64, s: u32| {
        let s = s as i32;
        EmptyElement::at((x, y))
            + PathElement::new(vec![(-s, -s), (s, s)], red.stroke_width(2))
            + PathElement::new(vec![(-s, s), (s, -s)], red.stroke_width(2))
    };
    let dot = (w / 250).max(3);
    {
        let unit = if absolute { "lux" } else { "relative" };
        let mut chart = ChartBuilder::on(&top)
            .margin((fs * 0.6) as u32)
            .x_label_area_size((fs * 1.8) as u32)
            .y_label_area_size((fs * 4.5) as u32)
            .build_cartesian_2d(x0..x1, (y0..y1).log_scale())
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .y_desc(format!("horizontal illuminance ({unit})"))
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format_tick(*v))
            .axis_desc_style((FONT_FAMILY, fs))
            .label_style((FONT_FAMILY, fs * 0.85))
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(215, 215, 215))
            .draw()
            .map_err(draw_err)?;
        let ok: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.state != DayState::Failed)
            .filter_map(|p| Some((p.hour_utc, p.illuminance.filter(|e| *e > 0.0)?)))
            .collect();
        chart
            .draw_series(LineSeries::new(ok.iter().copied(), ink.stroke_width(2)))
            .map_err(draw_err)?;
        chart
            .draw_series(points.iter().filter_map(|p| {
                let e = p.illuminance.filter(|e| *e > 0.0)?;
                match p.state {
                    DayState::Ok => Some(plotters::element::Circle::new(
                        (p.hour_utc, e),
                        dot,
                        ink.filled(),
                    )),
                    DayState::SunHidden => Some(plotters::element::Circle::new(
                        (p.hour_utc, e),
                        dot + 1,
                        grey.stroke_width(2),
                    )),
                    DayState::Failed => None,
                }
            }))
            .map_err(draw_err)?;
        let floor = y0 * 1.25;
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.state == DayState::Failed)
                    .map(|p| cross(p.hour_utc, floor, dot + 2)),
            )
            .map_err(draw_err)?;
    }
    {
        let mut chart = ChartBuilder::on(&bottom)
            .margin((fs * 0.6) as u32)
            .x_label_area_size((fs * 3.0) as u32)
            .y_label_area_size((fs * 4.5) as u32)
            .build_cartesian_2d(x0..x1, -10f64..90f64)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_desc("time of day (UTC, hours)")
            .y_desc("sun elevation (°)")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .axis_desc_style((FONT_FAMILY, fs))
            .label_style((FONT_FAMILY, fs * 0.85))
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(215, 215, 215))
            .draw()
            .map_err(draw_err)?;
        let sun = RGBColor(220, 140, 0);
        chart
            .draw_series(LineSeries::new(
                points
                    .iter()
                    .filter_map(|p| Some((p.hour_utc, p.sun_elevation_deg?))),
                sun.stroke_width(2),
            ))
            .map_err(draw_err)?;
        chart
            .draw_series(points.iter().filter_map(|p| {
                let el = p.sun_elevation_deg?;
                let style = match p.state {
                    DayState::Ok => sun.filled(),
                    _ => grey.stroke_width(2),
                };
                Some(plotters::element::Circle::new((p.hour_utc, el), dot, style))
            }))
            .map_err(draw_err)?;
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.state == DayState::Failed)
                    .map(|p| cross(p.hour_utc, -6.0, dot + 2)),
            )
            .map_err(draw_err)?;
    }
    Ok(())
}
