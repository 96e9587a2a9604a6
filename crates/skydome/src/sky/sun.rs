//! Finding the sun in a radiance image or a frame: a compact blob far brighter than the dome's
//! median (the method and its confidence are described in the module documentation).

use serde::{Deserialize, Serialize};

use super::{Direction, SkyError, SkyGeometry};
use crate::image::PixelPoint;
use crate::image::{luminance, Circle, HdrImage, RgbImage};

/// A detected sun.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SunDetection {
    /// Centroid of the sun blob, pixels.
    pub pixel: PixelPoint,
    /// Confidence in `[0, 1]` (see the module docs).
    pub confidence: f64,
    /// Blob area in pixels.
    pub area_px: usize,
    /// Peak (blurred) luminance over the dome's median luminance.
    pub peak_to_background: f64,
}

/// Finds the sun in a radiance image inside `region` (usually the horizon circle).
/// Returns `None` when no compact outstanding blob exists (overcast, sun hidden).
pub fn detect_sun(img: &HdrImage, region: &Circle) -> Option<SunDetection> {
    let luma: Vec<f32> = img.pixels().map(luminance).collect();
    detect_sun_luma(&luma, img.width, img.height, region)
        .ok()
        .flatten()
}

/// [`detect_sun`] on an 8-bit frame (codes used as they are: pick a mid exposure where the sun
/// is saturated but the sky is not).
pub fn detect_sun_u8(img: &RgbImage<u8>, region: &Circle) -> Option<SunDetection> {
    let luma: Vec<f32> = img
        .data
        .chunks_exact(3)
        .map(|c| luminance([f32::from(c[0]), f32::from(c[1]), f32::from(c[2])]))
        .collect();
    detect_sun_luma(&luma, img.width, img.height, region)
        .ok()
        .flatten()
}

/// [`detect_sun`] on a luminance buffer (`width * height`, row-major, origin top-left).
/// Errors only when the buffer size is wrong or the region is not a finite positive circle.
pub fn detect_sun_luma(
    luma: &[f32],
    width: usize,
    height: usize,
    region: &Circle,
) -> Result<Option<SunDetection>, SkyError> {
    crate::image::check_samples(luma.len(), width, height, 1)?;
    if !(region.r.is_finite() && region.r > 0.0 && region.cx.is_finite() && region.cy.is_finite()) {
        return Err(SkyError::BadParameter {
            what: "sun search radius (px)",
            value: region.r,
            hint: "give the dome's horizon circle",
        });
    }
    // Bounding box of the region inside the frame.
    let (xs, ys) = region.pixel_bounds(width, height);
    if xs.is_empty() || ys.is_empty() {
        return Ok(None);
    }
    let (x0, y0, bw, bh) = (xs.start, ys.start, xs.len(), ys.len());
    // Box blur of radius b over region pixels (outside pixels do not count).
    let b = ((region.r / 150.0).round() as usize).max(1);
    let blurred = region_box_mean(luma, width, (x0, y0, bw, bh), region, b);
    let Some((background, peak)) = median_and_peak(&blurred) else {
        return Ok(None);
    };
    let bg = background.max(peak * 1e-9).max(f32::MIN_POSITIVE);
    let ratio = f64::from(peak / bg);
    if !(peak > 0.0 && ratio >= 2.0) {
        return Ok(None);
    }
    let t = background + 0.5 * (peak - background);
    let mut blobs = blobs_above(&blurred, bw, bh, t, peak - background);
    blobs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let Some((best_energy, members)) = blobs.first() else {
        return Ok(None);
    };
    let runner_up = blobs.get(1).map_or(0.0, |c| c.0);
    let raw = |i: usize| {
        let v = luma[(y0 + i / bw) * width + x0 + i % bw];
        if v.is_finite() {
            v.max(0.0)
        } else {
            0.0
        }
    };
    let blob = Blob {
        members,
        bw,
        background,
    };
    let (sun_x, sun_y, compactness) = blob.centre_and_compactness(raw);
    let area = members.len() as f64;
    let r_eq = (area / std::f64::consts::PI).sqrt() / region.r;
    let size = ((0.20 - r_eq) / 0.12).clamp(0.0, 1.0);
    let contrast = (ratio.log10() / 2.0).clamp(0.0, 1.0);
    let ambiguity = 1.0 - (runner_up / best_energy).clamp(0.0, 1.0);
    let confidence = compactness * size * contrast * ambiguity;
    if confidence < 0.15 {
        return Ok(None);
    }
    Ok(Some(SunDetection {
        pixel: PixelPoint {
            x: x0 as f64 + sun_x,
            y: y0 as f64 + sun_y,
        },
        confidence,
        area_px: members.len(),
        peak_to_background: ratio,
    }))
}

/// The 8-connected blobs of `blurred` (`bw` × `bh`, NaN outside the region) at or above `t`,
/// each with its energy above `t` and its members (indices into `blurred`), in scan order.
/// `range` is the peak above the background: saturated plateaus have no energy above `t`, so
/// each member adds `1e-6 · range` and they still rank by area.
fn blobs_above(
    blurred: &[f32],
    bw: usize,
    bh: usize,
    t: f32,
    range: f32,
) -> Vec<(f64, Vec<usize>)> {
    let mut label = vec![0u32; bw * bh];
    let mut blobs: Vec<(f64, Vec<usize>)> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..bw * bh {
        if label[start] != 0 || blurred[start].is_nan() || blurred[start] < t {
            continue;
        }
        let id = blobs.len() as u32 + 1;
        label[start] = id;
        stack.push(start);
        let mut members = Vec::new();
        let mut energy = 0.0f64;
        while let Some(i) = stack.pop() {
            members.push(i);
            energy += f64::from(blurred[i] - t);
            let (x, y) = (i % bw, i / bw);
            for ny in y.saturating_sub(1)..(y + 2).min(bh) {
                for nx in x.saturating_sub(1)..(x + 2).min(bw) {
                    let j = ny * bw + nx;
                    if label[j] == 0 && blurred[j] >= t {
                        label[j] = id;
                        stack.push(j);
                    }
                }
            }
        }
        blobs.push((
            energy + 1e-6 * f64::from(range) * members.len() as f64,
            members,
        ));
    }
    blobs
}

/// The winning blob: its members (indices into a box `bw` wide) and the dome's background.
struct Blob<'a> {
    members: &'a [usize],
    bw: usize,
    background: f32,
}

impl Blob<'_> {
    /// The sun's centre in box pixels and the blob's compactness (its area over the area of
    /// the smallest disc around its centroid that holds it, at most 1), given the unblurred
    /// luminance `raw` of a member.
    ///
    /// Shape is judged around the blob's centroid; the sun's centre is the centroid of its core
    /// (raw values within the top tenth of the blob's range): the sky's gradient and glare skew
    /// the aureole around a clipped sun, not its saturated core.
    fn centre_and_compactness(&self, raw: impl Fn(usize) -> f32) -> (f64, f64, f64) {
        let (bw, background) = (self.bw, self.background);
        let core = self
            .members
            .iter()
            .map(|&i| raw(i))
            .fold(background, f32::max);
        let centroid = |floor: f32| {
            let (mut sx, mut sy, mut sw) = (0.0f64, 0.0f64, 0.0f64);
            for &i in self.members {
                let (x, y) = (i % bw, i / bw);
                let w = f64::from((raw(i) - floor).max(0.0)) + 1e-12;
                sx += w * (x as f64 + 0.5);
                sy += w * (y as f64 + 0.5);
                sw += w;
            }
            (sx / sw, sy / sw)
        };
        let (mx, my) = centroid(background);
        let (sun_x, sun_y) = centroid(background + 0.9 * (core - background));
        let rmax = self
            .members
            .iter()
            .map(|&i| ((i % bw) as f64 + 0.5 - mx).hypot((i / bw) as f64 + 0.5 - my))
            .fold(0.0f64, f64::max)
            + 0.5;
        let area = self.members.len() as f64;
        let compactness = (area / (std::f64::consts::PI * rmax * rmax)).min(1.0);
        (sun_x, sun_y, compactness)
    }
}

/// What the search for the sun in a dome knows besides its pixels ([`find_sun`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct SunClues<'a> {
    /// Per pixel of the image (row-major, its size): `true` where the pixel clipped even in the
    /// shortest exposure (the merge's `CLIPPED_HIGH`), so its radiance is a lower bound.
    pub clipped: Option<&'a [bool]>,
    /// Where time and site put the sun (the ephemeris) and how far from it, in degrees, a
    /// detection is still taken for it (the compass's and the lens model's errors): a sun-like
    /// blob within it wins over any other.
    pub prior: Option<(Direction, f64)>,
}

/// Clipped cores larger than this (equivalent angular radius, degrees) are no sun: the disc is
/// 0.53° across, and glare in a clipped frame grows it by a few pixels, not by degrees.
pub const SUN_CORE_MAX_DEG: f64 = 4.5;

/// A blob brighter than this many times the dome's median is sun-bright even where nothing
/// clipped (the sun is ~10⁵ times the sky; a lit cloud is at most some tens of times).
pub const SUN_BRIGHT_RATIO: f64 = 300.0;

/// Finds the sun in a dome `img` seen through `geom` (the search covers the horizon circle,
/// `θ ≤ 90°`), with what else is known (`clues`). Unlike [`detect_sun`], which judges the blob
/// above half the peak, it judges each bright blob by its **core** — the pixels that clipped in
/// every frame, or within 10 % of the blob's maximum where none clipped — so a circumsolar
/// aureole clipping thousands of pixels of the longer frames does not hide the sun, and a lit
/// cloud does not pass for one:
///
/// - a sun is **sun-bright**: its core clipped even in the shortest exposure, or it is
///   [`SUN_BRIGHT_RATIO`] times the median; a cloud that did not clip in the shortest frame is
///   never the sun;
/// - its core is **small** (equivalent angular radius, from the projection's solid angle per
///   pixel, at most [`SUN_CORE_MAX_DEG`]) and **compact** (at least 30 % of the disc around its
///   centroid that holds it, measured in angle, so a low sun flattened by the projection counts
///   as round): a clipped cloud is large or ragged;
/// - with a prior (time and site known), a blob within its radius wins, the nearest first.
///
/// The sun's centre is the centroid of its core. Confidence = compactness × contrast
/// (`log10(peak/median)/2`, capped at 1) × size (1 up to a core of 1°, falling to 0 at
/// [`SUN_CORE_MAX_DEG`]) × ambiguity (`1 −` the runner-up's score over the winner's); below
/// 0.15, or with no sun-like blob, `None`.
pub fn find_sun(
    img: &HdrImage,
    geom: &SkyGeometry,
    clues: &SunClues<'_>,
) -> Result<Option<SunDetection>, SkyError> {
    let (width, height) = (img.width, img.height);
    if let Some(c) = clues.clipped {
        crate::image::check_samples(c.len(), width, height, 1)?;
    }
    let region = geom.horizon_circle();
    if !(region.r.is_finite() && region.r > 0.0) {
        return Ok(None);
    }
    let luma = luminance_plane(img);
    let (xs, ys) = region.pixel_bounds(width, height);
    if xs.is_empty() || ys.is_empty() {
        return Ok(None);
    }
    let (x0, y0, bw, bh) = (xs.start, ys.start, xs.len(), ys.len());
    let b = ((region.r / 150.0).round() as usize).max(1);
    let blurred = region_box_mean(&luma, width, (x0, y0, bw, bh), &region, b);
    let Some((background, _)) = median_and_peak(&blurred) else {
        return Ok(None);
    };
    let at = |i: usize| (y0 + i / bw) * width + x0 + i % bw;
    let raw = |i: usize| {
        let v = luma[at(i)];
        if v.is_finite() {
            v.max(0.0)
        } else {
            0.0
        }
    };
    let clipped = |i: usize| clues.clipped.is_some_and(|c| c[at(i)]);
    let (map, peak) = search_map(&luma, width, (x0, y0, bw), &blurred, clues.clipped);
    let bg = background.max(peak * 1e-9).max(f32::MIN_POSITIVE);
    if !(peak > 0.0 && f64::from(peak / bg) >= 2.0) {
        return Ok(None);
    }
    let t = background + 0.5 * (peak - background);
    let mut blobs = blobs_above(&map, bw, bh, t, peak - background);
    blobs.sort_by(|a, b| b.0.total_cmp(&a.0));
    blobs.truncate(16);
    // Solid angle of the pixel at box index i (sr): sin θ / (r'(θ) · r(θ)) per px².
    let proj = geom.projection();
    let (cx, cy) = geom.centre();
    let solid_angle = |x: f64, y: f64| -> f64 {
        let r = (x - cx).hypot(y - cy).max(0.5);
        match proj.theta(r) {
            Some(th) => th.sin() / (proj.derivative(th) * r),
            None => 0.0,
        }
    };
    struct Candidate {
        x: f64,
        y: f64,
        score: f64,
        compactness: f64,
        core_deg: f64,
        contrast: f64,
        area: usize,
        ratio: f64,
        off_prior: Option<f64>,
    }
    let mut candidates = Vec::new();
    for (_, members) in &blobs {
        let m = members.iter().map(|&i| raw(i)).fold(0.0f32, f32::max);
        let any_clipped = members.iter().any(|&i| clipped(i));
        let core: Vec<usize> = match any_clipped {
            // Closed (3 × 3): a JPEG's ringing leaves a clipped core with unflagged holes and
            // gaps (a pixel reading 253 in the shortest frame), which would make a round sun
            // look ragged.
            true => close_within(
                &members
                    .iter()
                    .copied()
                    .filter(|&i| clipped(i))
                    .collect::<Vec<_>>(),
                members,
                bw,
            ),
            false => members
                .iter()
                .copied()
                .filter(|&i| raw(i) >= 0.9 * m)
                .collect(),
        };
        let ratio = f64::from(m / bg);
        // At the dome's ceiling: the brightest thing in it, ten times the median (a pixel JPEG
        // pulled down to 253 in the shortest frame is clipped but not flagged).
        let at_ceiling = m >= 0.8 * peak && ratio >= 10.0;
        if !(any_clipped || at_ceiling || ratio >= SUN_BRIGHT_RATIO) || core.is_empty() {
            continue;
        }
        // Without a clipped pixel, a small core is all that tells the sun from a lit cloud.
        let core_limit = match any_clipped || ratio >= SUN_BRIGHT_RATIO {
            true => SUN_CORE_MAX_DEG,
            false => 1.0,
        };
        // Centre: the core's centroid, weighted by luminance above the core's floor.
        let floor = core.iter().map(|&i| raw(i)).fold(f32::INFINITY, f32::min);
        let (mut sx, mut sy, mut sw, mut omega) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let (mut ux, mut uy) = (0.0f64, 0.0f64);
        for &i in &core {
            let (x, y) = ((x0 + i % bw) as f64 + 0.5, (y0 + i / bw) as f64 + 0.5);
            let w = f64::from(raw(i) - floor) + 1e-6 * f64::from(m.max(1e-30));
            sx += w * x;
            sy += w * y;
            sw += w;
            ux += x;
            uy += y;
            omega += solid_angle(x, y);
        }
        let _ = (sx, sy, sw);
        // The centre as the blob's brightest tenth says it (sub-pixel: a pixel the disc only
        // touches clips in fewer channels and reads dimmer).
        let top = background + 0.9 * (m - background);
        let (mut tx, mut ty, mut tw) = (0.0f64, 0.0f64, 0.0f64);
        for &i in members.iter() {
            let v = raw(i);
            if v >= top {
                let w = f64::from(v - top) + 1e-12;
                tx += w * ((x0 + i % bw) as f64 + 0.5);
                ty += w * ((y0 + i / bw) as f64 + 0.5);
                tw += w;
            }
        }
        let (mut x, mut y) = (tx / tw, ty / tw);
        // A core of a pixel or two: refine over the 3 × 3 pixels around it, weighted by their
        // excess over the ring of pixels two away (the aureole), so the neighbours the disc or
        // its glare touched pull the centre by how much they caught.
        if core.len() <= 2 {
            let (px, py) = (x.floor() as i64, y.floor() as i64);
            let get = |dx: i64, dy: i64| -> Option<f32> {
                let (qx, qy) = (px + dx, py + dy);
                (qx >= 0 && qy >= 0 && (qx as usize) < width && (qy as usize) < height)
                    .then(|| luma[qy as usize * width + qx as usize])
                    .filter(|v| v.is_finite())
            };
            let mut ring: Vec<f32> = Vec::new();
            for d in -2i64..=2 {
                for (dx, dy) in [(d, -2), (d, 2), (-2, d), (2, d)] {
                    ring.extend(get(dx, dy));
                }
            }
            if !ring.is_empty() {
                ring.sort_by(f32::total_cmp);
                let floor = ring[ring.len() / 2];
                let (mut ax, mut ay, mut aw) = (0.0f64, 0.0f64, 0.0f64);
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        if let Some(v) = get(dx, dy) {
                            let w = f64::from((v - floor).max(0.0));
                            ax += w * ((px + dx) as f64 + 0.5);
                            ay += w * ((py + dy) as f64 + 0.5);
                            aw += w;
                        }
                    }
                }
                if aw > 0.0 {
                    (x, y) = (ax / aw, ay / aw);
                }
            }
        }
        let n = core.len() as f64;
        let (ux, uy) = (ux / n, uy / n);
        let core_deg = (omega / std::f64::consts::PI).sqrt().to_degrees();
        if core_deg > core_limit {
            continue;
        }
        let Some(centre) = geom.pixel_to_vector(x, y) else {
            continue;
        };
        // Compactness in angle: the core's solid angle over the cap around its (unweighted)
        // centroid that holds every core pixel, half a pixel added; a core of a few pixels
        // has no shape to judge.
        let compactness = match (core.len() < 5, geom.pixel_to_vector(ux, uy)) {
            (true, _) | (_, None) => 1.0,
            (false, Some(mid)) => {
                let mut reach = 0.0f64;
                for &i in &core {
                    let (px, py) = ((x0 + i % bw) as f64 + 0.5, (y0 + i / bw) as f64 + 0.5);
                    if let Some(v) = geom.pixel_to_vector(px, py) {
                        let c = (v[0] * mid[0] + v[1] * mid[1] + v[2] * mid[2]).clamp(-1.0, 1.0);
                        reach = reach.max(c.acos());
                    }
                }
                let rr = (ux - cx).hypot(uy - cy).max(0.5);
                let half_px = proj.theta(rr).map_or(0.0, |th| 0.5 / proj.derivative(th));
                let reach = reach + half_px;
                let cap = 2.0 * std::f64::consts::PI * (1.0 - reach.cos());
                (omega / cap).min(1.0)
            }
        };
        if compactness < 0.3 {
            continue;
        }
        let off_prior = clues
            .prior
            .map(|(d, _)| Direction::from_vector(centre).angle_to(&d));
        let contrast = (ratio.log10() / 2.0).clamp(0.0, 1.0);
        let size = ((SUN_CORE_MAX_DEG - core_deg) / (SUN_CORE_MAX_DEG - 1.0)).clamp(0.0, 1.0);
        candidates.push(Candidate {
            x,
            y,
            score: compactness * contrast * size,
            compactness,
            core_deg,
            contrast,
            area: members.len(),
            ratio,
            off_prior,
        });
    }
    // With a prior a sun-like blob within its radius wins, the nearest first; otherwise (or
    // when none is within it: a compass far off) the best scored.
    let radius = clues.prior.map_or(0.0, |(_, r)| r);
    let near = |c: &Candidate| c.off_prior.is_some_and(|o| o <= radius);
    candidates.sort_by(|a, b| match (near(a), near(b)) {
        (true, true) => a
            .off_prior
            .unwrap_or(0.0)
            .total_cmp(&b.off_prior.unwrap_or(0.0)),
        (true, false) => std::cmp::Ordering::Less,
        (false, true) => std::cmp::Ordering::Greater,
        (false, false) => b.score.total_cmp(&a.score),
    });
    let Some(best) = candidates.first() else {
        return Ok(None);
    };
    let runner_up = candidates
        .iter()
        .skip(1)
        .map(|c| c.score)
        .fold(0.0f64, f64::max);
    let ambiguity = match near(best) {
        // The prior settles which is the sun.
        true => 1.0,
        false => 1.0 - (runner_up / best.score.max(1e-12)).clamp(0.0, 1.0),
    };
    let size = ((SUN_CORE_MAX_DEG - best.core_deg) / (SUN_CORE_MAX_DEG - 1.0)).clamp(0.0, 1.0);
    let confidence = best.compactness * best.contrast * size * ambiguity;
    if confidence < 0.15 {
        return Ok(None);
    }
    Ok(Some(SunDetection {
        pixel: PixelPoint {
            x: best.x,
            y: best.y,
        },
        confidence,
        area_px: best.area,
        peak_to_background: best.ratio,
    }))
}

/// The morphological closing (a 3 × 3 dilation, then a 3 × 3 erosion) of the pixel set `set`
/// (indices into a box `bw` wide), kept to `members`, in scan order: holes and gaps a pixel or
/// two wide inside `set` are filled, its outline stays where it was.
fn close_within(set: &[usize], members: &[usize], bw: usize) -> Vec<usize> {
    let Some((&first, _)) = set.split_first() else {
        return Vec::new();
    };
    // A local grid around the set, two pixels of margin (the dilation's reach plus the
    // erosion's), in signed box coordinates.
    let xy = |i: usize| ((i % bw) as i64, (i / bw) as i64);
    let (mut lx, mut ly, mut hx, mut hy) = {
        let (x, y) = xy(first);
        (x, y, x, y)
    };
    for &i in set {
        let (x, y) = xy(i);
        (lx, ly, hx, hy) = (lx.min(x), ly.min(y), hx.max(x), hy.max(y));
    }
    let (lx, ly) = (lx - 2, ly - 2);
    let (gw, gh) = ((hx + 3 - lx) as usize, (hy + 3 - ly) as usize);
    let cell = |x: i64, y: i64| -> Option<usize> {
        let (gx, gy) = (x - lx, y - ly);
        (gx >= 0 && gy >= 0 && (gx as usize) < gw && (gy as usize) < gh)
            .then(|| gy as usize * gw + gx as usize)
    };
    let mut grid = vec![false; gw * gh];
    for &i in set {
        let (x, y) = xy(i);
        if let Some(c) = cell(x, y) {
            grid[c] = true;
        }
    }
    let around = |g: &[bool], x: i64, y: i64, all: bool| {
        let mut n = (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy)));
        let hit = |(a, b): (i64, i64)| cell(a, b).is_some_and(|c| g[c]);
        match all {
            true => n.all(hit),
            false => n.any(hit),
        }
    };
    let dilated: Vec<bool> = (0..gw * gh)
        .map(|c| around(&grid, lx + (c % gw) as i64, ly + (c / gw) as i64, false))
        .collect();
    members
        .iter()
        .copied()
        .filter(|&i| {
            let (x, y) = xy(i);
            cell(x, y).is_some_and(|c| grid[c]) || around(&dilated, x, y, true)
        })
        .collect()
}

/// The luminance of every pixel of `img` (row-major), rows in parallel with the `parallel`
/// feature.
fn luminance_plane(img: &HdrImage) -> Vec<f32> {
    let lum = |p: &[f32]| luminance([p[0], p[1], p[2]]);
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        img.data.par_chunks_exact(3).map(lum).collect()
    }
    #[cfg(not(feature = "parallel"))]
    img.data.chunks_exact(3).map(lum).collect()
}

/// [`find_sun`]'s search map over the box `x0..x0 + bw` of rows `y0..` (`blurred.len() / bw`
/// of them) of the `width`-wide `luma`: the blurred luminance (against noise), but a pixel
/// flagged in `clipped` keeps its own (a clipped core of a pixel or two would otherwise be
/// blurred into its aureole); `NaN` where `blurred` is (outside the region). With the map's
/// largest value (0 when there is none above 0). Rows in parallel with the `parallel` feature:
/// both the map and its maximum are the same in any order.
fn search_map(
    luma: &[f32],
    width: usize,
    (x0, y0, bw): (usize, usize, usize),
    blurred: &[f32],
    clipped: Option<&[bool]>,
) -> (Vec<f32>, f32) {
    let mut map = vec![0.0f32; blurred.len()];
    let row = |(y, out): (usize, &mut [f32])| -> f32 {
        let start = (y0 + y) * width + x0;
        let src = &luma[start..start + bw];
        let flags = clipped.map(|c| &c[start..start + bw]);
        let b = &blurred[y * bw..(y + 1) * bw];
        let mut peak = 0.0f32;
        for x in 0..bw {
            let v = match b[x].is_nan() {
                true => f32::NAN,
                false if flags.is_some_and(|f| f[x]) => match src[x].is_finite() {
                    true => src[x].max(0.0),
                    false => 0.0,
                },
                false => b[x],
            };
            out[x] = v;
            if !v.is_nan() {
                peak = peak.max(v);
            }
        }
        peak
    };
    #[cfg(feature = "parallel")]
    let peak = {
        use rayon::prelude::*;
        map.par_chunks_mut(bw.max(1))
            .enumerate()
            .map(row)
            .reduce(|| 0.0f32, f32::max)
    };
    #[cfg(not(feature = "parallel"))]
    let peak = map
        .chunks_mut(bw.max(1))
        .enumerate()
        .map(row)
        .fold(0.0f32, f32::max);
    (map, peak)
}

/// The median (the `n/2`-th smallest, as `select_nth_unstable`) and the largest of the
/// non-NaN values (all non-negative and finite here), or `None` for fewer than 16.
///
/// Exact, in two passes instead of a copy and a selection of millions of values: for
/// non-negative floats the bit patterns sort as the values do, so a histogram of the top 16
/// bits finds the bin holding the median, and only that bin's values are selected among.
fn median_and_peak(values: &[f32]) -> Option<(f32, f32)> {
    // Counts per bin, the number of values and the largest, of one run of values; runs in
    // parallel with the `parallel` feature (counts add up, the largest is the same in any
    // order).
    let count = |part: &[f32]| {
        let mut hist = vec![0u32; 1 << 16];
        let (mut n, mut peak) = (0usize, 0.0f32);
        for &v in part.iter().filter(|v| !v.is_nan()) {
            hist[(v.to_bits() >> 16) as usize] += 1;
            n += 1;
            peak = crate::fastmath::max(v, peak);
        }
        (hist, n, peak)
    };
    #[cfg(feature = "parallel")]
    let (hist, n, peak) = {
        use rayon::prelude::*;
        // Parts of at least a million values: each part's table is 256 KiB.
        values
            .par_chunks(1 << 20)
            .map(count)
            .reduce_with(|(mut h, n, p), (h2, n2, p2)| {
                h.iter_mut().zip(&h2).for_each(|(a, b)| *a += b);
                (h, n + n2, crate::fastmath::max(p2, p))
            })
            .unwrap_or_else(|| count(&[]))
    };
    #[cfg(not(feature = "parallel"))]
    let (hist, n, peak) = count(values);
    if n < 16 {
        return None;
    }
    let mut rank = n / 2;
    let mut bin = 0;
    for (b, &count) in hist.iter().enumerate() {
        if rank < count as usize {
            bin = b as u32;
            break;
        }
        rank -= count as usize;
    }
    let mut in_bin: Vec<f32> = values
        .iter()
        .copied()
        .filter(|v| !v.is_nan() && v.to_bits() >> 16 == bin)
        .collect();
    let median = *in_bin.select_nth_unstable_by(rank, f32::total_cmp).1;
    Some((median, peak))
}

/// Mean of the pixels of `region` in the `(2b + 1)²` window around each pixel of the box
/// `x0..x0 + bw`, `y0..y0 + bh` (row-major, `bw * bh`; outside pixels `NaN` and not counted;
/// non-finite values count as 0, negative ones are clamped to 0).
///
/// Separable running sums (per row a prefix sum over the row's inside span, then per column a
/// sliding sum over `2b + 1` rows, both in `f64`): two operations per pixel instead of the
/// window's `(2b + 1)²` — a 12 MP dome has `b = 11`, 529 — which made the sun search cost more
/// than decoding the frames. Row bands run in parallel with the `parallel` feature.
fn region_box_mean(
    luma: &[f32],
    width: usize,
    (x0, y0, bw, bh): (usize, usize, usize, usize),
    region: &Circle,
    b: usize,
) -> Vec<f32> {
    // Each row's inside pixels form one span `lo..hi` (box coordinates): the circle is convex.
    let spans: Vec<(usize, usize)> = (0..bh)
        .map(|y| {
            let (a, e) = region.row_span(y0 + y, x0 + bw);
            let (lo, hi) = (a.max(x0) - x0, e.max(x0) - x0);
            (lo, hi.max(lo))
        })
        .collect();
    let rows = &luma[y0 * width..];
    let hsum = row_window_sums(rows, width, x0, bw, &spans, b);
    column_window_means(&hsum, bw, &spans, b)
}

/// Per row `y` of the box (its samples at `rows[y * width + x0..][..bw]`), the sum of the
/// values inside the row's span in the window `x − b ..= x + b` around each pixel (0 outside
/// the span; non-finite values count as 0, negative ones as 0).
fn row_window_sums(
    rows: &[f32],
    width: usize,
    x0: usize,
    bw: usize,
    spans: &[(usize, usize)],
    b: usize,
) -> Vec<f32> {
    let raw = |v: f32| if v.is_finite() { v.max(0.0) } else { 0.0 };
    let mut hsum = vec![0.0f32; bw * spans.len()];
    let horizontal = |(y, row): (usize, &mut [f32])| {
        let (lo, hi) = spans[y];
        if hi <= lo {
            return;
        }
        let src = &rows[y * width + x0..][..bw];
        let mut prefix = Vec::with_capacity(hi - lo + 1);
        let mut acc = 0.0f64;
        prefix.push(0.0f64);
        for &v in &src[lo..hi] {
            acc += f64::from(raw(v));
            prefix.push(acc);
        }
        for (x, o) in row.iter_mut().enumerate() {
            let a = x.saturating_sub(b).max(lo);
            let e = (x + b + 1).min(hi);
            if e > a {
                *o = (prefix[e - lo] - prefix[a - lo]) as f32;
            }
        }
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        hsum.par_chunks_mut(bw).enumerate().for_each(horizontal);
    }
    #[cfg(not(feature = "parallel"))]
    hsum.chunks_mut(bw).enumerate().for_each(horizontal);
    hsum
}

/// The window means from [`row_window_sums`]: vertical sliding sums over `2b + 1` rows of the
/// sums and of the inside-pixel counts (which follow from the spans), each band of 64 rows
/// starting its own window; `NaN` outside the spans.
fn column_window_means(hsum: &[f32], bw: usize, spans: &[(usize, usize)], b: usize) -> Vec<f32> {
    let bh = spans.len();
    let count = |x: usize, y: usize| {
        let (lo, hi) = spans[y];
        let a = x.saturating_sub(b).max(lo);
        let e = (x + b + 1).min(hi);
        e.saturating_sub(a)
    };
    const BAND: usize = 64;
    let mut out = vec![f32::NAN; bw * bh];
    let vertical = |(k, band): (usize, &mut [f32])| {
        let ys = k * BAND;
        let mut s = vec![0.0f64; bw];
        let mut n = vec![0usize; bw];
        let window = |y: usize| y.saturating_sub(b)..(y + b + 1).min(bh);
        for yy in window(ys) {
            for x in 0..bw {
                s[x] += f64::from(hsum[yy * bw + x]);
                n[x] += count(x, yy);
            }
        }
        for (r, row) in band.chunks_exact_mut(bw).enumerate() {
            let y = ys + r;
            if r > 0 {
                // Slide: row y + b enters, row y − b − 1 leaves.
                if y + b < bh {
                    let add = &hsum[(y + b) * bw..][..bw];
                    for x in 0..bw {
                        s[x] += f64::from(add[x]);
                        n[x] += count(x, y + b);
                    }
                }
                if y > b {
                    let sub = &hsum[(y - b - 1) * bw..][..bw];
                    for x in 0..bw {
                        s[x] -= f64::from(sub[x]);
                        n[x] -= count(x, y - b - 1);
                    }
                }
            }
            let (lo, hi) = spans[y];
            for x in lo..hi {
                row[x] = (s[x] / n[x] as f64) as f32;
            }
        }
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(BAND * bw).enumerate().for_each(vertical);
    }
    #[cfg(not(feature = "parallel"))]
    out.chunks_mut(BAND * bw).enumerate().for_each(vertical);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window mean the way it reads: every window pixel tested, summed in `f64`.
    fn box_mean_by_definition(
        luma: &[f32],
        width: usize,
        (x0, y0, bw, bh): (usize, usize, usize, usize),
        region: &Circle,
        b: usize,
    ) -> Vec<f32> {
        let inside = |x: usize, y: usize| region.contains_pixel(x0 + x, y0 + y);
        let mut out = vec![f32::NAN; bw * bh];
        for y in 0..bh {
            for x in 0..bw {
                if !inside(x, y) {
                    continue;
                }
                let (mut s, mut n) = (0.0f64, 0.0f64);
                for yy in y.saturating_sub(b)..(y + b + 1).min(bh) {
                    for xx in x.saturating_sub(b)..(x + b + 1).min(bw) {
                        if inside(xx, yy) {
                            let v = luma[(y0 + yy) * width + x0 + xx];
                            s += if v.is_finite() {
                                f64::from(v.max(0.0))
                            } else {
                                0.0
                            };
                            n += 1.0;
                        }
                    }
                }
                out[y * bw + x] = (s / n) as f32;
            }
        }
        out
    }

    #[test]
    fn closing_fills_a_clipped_cores_holes_not_its_outline() {
        // A 7 × 5 box; the set is a ring with a hole and a one-pixel gap; members cover it all.
        let bw = 7;
        let at = |x: usize, y: usize| y * bw + x;
        let set = [
            at(2, 1),
            at(3, 1),
            at(4, 1),
            at(2, 2),
            at(4, 2),
            at(2, 3),
            at(4, 3),
        ];
        let members: Vec<usize> = (0..bw * 5).collect();
        let mut closed = close_within(&set, &members, bw);
        closed.sort_unstable();
        let mut want = set.to_vec();
        want.extend([at(3, 2), at(3, 3)]);
        want.sort_unstable();
        assert_eq!(closed, want);
        // Kept to the members: a filled pixel that is not a member stays out.
        let members: Vec<usize> = members.into_iter().filter(|&i| i != at(3, 2)).collect();
        assert!(!close_within(&set, &members, bw).contains(&at(3, 2)));
        assert!(close_within(&[], &members, bw).is_empty());
    }

    #[test]
    fn median_by_histogram_is_the_selected_median() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        // 2.5 million: three parts of the parallel histogram, added up.
        for n in [16usize, 17, 100, 4097, 100_000, 2_500_000] {
            for spread in [1.0f32, 1e-3, 1e6] {
                let v: Vec<f32> = (0..n)
                    .map(|i| {
                        state ^= state << 13;
                        state ^= state >> 7;
                        state ^= state << 17;
                        match i % 50 {
                            0 => f32::NAN,
                            1 => 0.0,
                            // Ties: many equal values.
                            2..=9 => 0.5 * spread,
                            _ => (state % 1_000_000) as f32 / 1e6 * spread,
                        }
                    })
                    .collect();
                let mut finite: Vec<f32> = v.iter().copied().filter(|x| !x.is_nan()).collect();
                let mid = finite.len() / 2;
                let want = *finite.select_nth_unstable_by(mid, f32::total_cmp).1;
                let peak = finite.iter().copied().fold(0.0f32, f32::max);
                let want = (finite.len() >= 16).then_some((want, peak));
                assert_eq!(median_and_peak(&v), want, "n {n} spread {spread}");
            }
        }
        assert_eq!(median_and_peak(&[1.0; 15]), None);
        assert_eq!(median_and_peak(&[f32::NAN; 40]), None);
    }

    #[test]
    fn running_box_mean_equals_the_window_mean_by_definition() {
        // Circles centred on and off pixel corners, cut by the frame's edges or not, windows
        // from 1 to wider than the circle; values over 12 decades with NaN, ∞ and negatives.
        let (w, h) = (157usize, 131usize);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let luma: Vec<f32> = (0..w * h)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                match state % 97 {
                    0 => f32::NAN,
                    1 => f32::INFINITY,
                    2 => -3.0,
                    k => 10f32.powf((k as f32 / 8.0) - 6.0),
                }
            })
            .collect();
        let circles = [
            Circle {
                cx: 78.5,
                cy: 65.5,
                r: 60.0,
            },
            Circle {
                cx: 70.0,
                cy: 60.0,
                r: 80.3,
            },
            Circle {
                cx: 10.2,
                cy: 120.7,
                r: 33.3,
            },
            Circle {
                cx: 150.0,
                cy: 3.0,
                r: 4.6,
            },
            Circle {
                cx: 40.5,
                cy: 40.5,
                r: 0.7,
            },
        ];
        for region in &circles {
            let x0 = (region.cx - region.r).floor().max(0.0) as usize;
            let y0 = (region.cy - region.r).floor().max(0.0) as usize;
            let x1 = ((region.cx + region.r).ceil() as usize).min(w);
            let y1 = ((region.cy + region.r).ceil() as usize).min(h);
            let bx = (x0, y0, x1 - x0, y1 - y0);
            for b in [1, 2, 5, 11, 200] {
                let fast = region_box_mean(&luma, w, bx, region, b);
                let slow = box_mean_by_definition(&luma, w, bx, region, b);
                for (i, (f, s)) in fast.iter().zip(&slow).enumerate() {
                    assert_eq!(
                        f.is_nan(),
                        s.is_nan(),
                        "inside test at {i}, {region:?}, b {b}"
                    );
                    if !s.is_nan() {
                        assert!(
                            (f - s).abs() <= 1e-5 * s.abs() + 1e-30,
                            "{f} vs {s} at {i}, {region:?}, b {b}"
                        );
                    }
                }
            }
        }
    }
}
