//! The sun from 3° to 90° against Radiance's own skies (issue 22).
//!
//! `scripts/radiance_sweep.py` renders Perez skies (`gendaylit` + `rpict -vta`, from the
//! `pyradiance` package, found through `SKYDOME_PYTHON`) into a cache under `target/`, keyed by
//! their parameters (solar elevation 3–90° × azimuth × clear, hazy, intermediate and overcast
//! skies × a bright cloud over the sun or elsewhere × trees or buildings on the horizon ×
//! exposure × 2, 3 or 5 frames × 180°/190° lenses):
//! - `sweep`: 72 scenes split by seed 22 into a tune and a first held-out half; the detector was
//!   tuned on the first and the second was looked at while tuning, so neither is held out now
//!   (`SKYDOME_SUN_SWEEP=all` scores them);
//! - `fresh`: 30 scenes from seed 2211, 6 per elevation band, rendered after the detector was
//!   frozen and measured on it untouched — the **held-out** set whose numbers `docs/station.md`
//!   gives and [`held_out_suns_are_found_and_no_false_one`] holds; CI scores its six-scene `ci`
//!   part (chosen by what the scenes show, before any was scored), `SKYDOME_SUN_SWEEP=fresh`
//!   all 30;
//! - `holdout`: 30 scenes from seed 2212 (2–5 frames), rendered after the finder was frozen
//!   again (the shortest frame's ceiling codes counted as clipped, a change made looking at
//!   `fresh`, which is therefore spent) and scored once — the **held-out** set of
//!   `docs/station.md` now; `SKYDOME_SUN_SWEEP=holdout` or `all`;
//! - `day`: one station's day (one capture an hour, some suns behind clouds, time and site as
//!   EXIF gives them), `SKYDOME_SUN_SWEEP=day` or `all`;
//! - `issue`: the issue's own case, always.
//!
//! Each scene is photographed here by the project's camera simulation ([`synth::photograph`]: a
//! lens losing half its light at the horizon, shot and read noise, an 8-bit response, JPEG) and
//! merged by [`pipeline::run`] with the sun found automatically.
//!
//! Scored per scene: a visible sun (not behind a cloud or an obstacle, direct normal > 0) must be
//! found, and its angular error is measured; a sun reported where none is visible, or more than
//! 2° from the visible one, is a **false sun**. With a spot luminance and the horizontal
//! illuminance of the render as meter readings, the reconstructed direct normal and diffuse
//! horizontal illuminance are compared with gendaylit's inputs.
//!
//! CI renders 7 scenes (about a minute and a half on 2 cores) and the day's 16 for the camera
//! made absolute once ([`absolute_day`], about 1.7 min more on the loaded 2-core machine); the
//! cache makes reruns free.

use crate::common;

mod absolute_day;
use std::path::{Path, PathBuf};
use std::process::Command;

use skydome::bracket::{CaptureInfo, DecodedFrame};
use skydome::fisheye::{LensKind, LensProfile, Vignetting};
use skydome::image::{Circle, HdrImage};
use skydome::photometry::{Reference, SpotLuminance};
use skydome::pipeline::{self, Frames, Input, LensSource, Options, SkyOptions, SunDisc, SunMode};
use skydome::sky::{radiance_luminance, DevicePose, Direction, ImageOrientation, SkyGeometry};
use skydome::synth::{self, SynthOptions};

/// The share of visible suns of the fresh held-out set the detector must find: measured 20 of
/// 20 (see `docs/station.md`), held with a margin of one sun in 20.
const FRESH_FOUND_MIN: f64 = 0.95;

/// The largest angular error (degrees) allowed on the fresh held-out set: the 0.5°
/// target (measured: 0.23°).
const FRESH_ERROR_MAX_DEG: f64 = 0.5;

/// The largest |direct normal error| of a rebuilt (clipped) sun on the fresh held-out set:
/// measured 32.1 % (a hazy sun 4.3° up; 30.8 % before the ceiling codes counted as clipped),
/// held at 35 %.
const FRESH_DIRECT_MAX: f64 = 0.35;

/// False suns allowed on the fresh set: none. Its one false sun (`fresh23`: a sun behind a
/// cloud 10× the diffuse sky, 2 frames, one cloud pixel at 255 in the shorter frame) went when
/// the shortest frame's ceiling codes counted as clipped: the cloud's clipped region is seen
/// whole, too large and ragged for a sun. The fresh set was looked at for that change, so it is
/// no longer held out; the `holdout` set is.
const FRESH_KNOWN_FALSE_SUNS: &[&str] = &[];

/// The largest |dome horizontal illuminance error| on the fresh set, against the meter reading
/// (which also sets a rebuilt disc's direct part): measured 4.3 % (`fresh23`, the sun behind a
/// cloud: nothing to rebuild); before the ceiling codes counted as clipped 40–87 % in four
/// scenes whose visible sun read 251–254 in the shortest frame. Held at 8 %.
const FRESH_DOME_MAX: f64 = 0.08;

/// A rendered scene and what it was made of (`truth.json`).
#[derive(Debug, Clone, serde::Deserialize)]
struct Truth {
    name: String,
    split: String,
    sky: String,
    size: usize,
    fov_deg: f64,
    sun_azimuth_deg: f64,
    sun_elevation_deg: f64,
    sun_visible: bool,
    #[serde(default)]
    sun_partly_hidden: bool,
    hidden_by: Option<String>,
    direct_normal_lux: f64,
    diffuse_horizontal_lux: f64,
    camera: Camera,
    time: Option<String>,
    latitude_deg: Option<f64>,
    longitude_deg: Option<f64>,
    clouds: Vec<serde_json::Value>,
    obstacles: Vec<serde_json::Value>,
}

#[derive(Debug, Clone, serde::Deserialize)]
struct Camera {
    ev_offset: f64,
    evs: Vec<f64>,
    seed: u64,
}

struct Scene {
    truth: Truth,
    image: HdrImage,
}

/// Renders (or finds in the cache) the scenes of `set` (and `split`), `None` without pyradiance.
fn scenes(set: &str, split: &str) -> Option<Vec<Scene>> {
    common::radiance_tools()?;
    let py = common::required::python();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"));
    let out = Command::new(&py)
        .arg(root.join("scripts/radiance_sweep.py"))
        .args(["--out"])
        .arg(target.join("radiance-sweep"))
        .args(["--set", set, "--split", split])
        .output()
        .expect("run scripts/radiance_sweep.py");
    assert!(
        out.status.success(),
        "radiance_sweep.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let list = String::from_utf8(out.stdout).expect("utf-8");
    Some(
        list.lines()
            .map(|dir| {
                let dir = Path::new(dir);
                let truth: Truth = serde_json::from_slice(
                    &std::fs::read(dir.join("truth.json")).expect("truth.json"),
                )
                .expect("parse truth.json");
                let image = skydome::formats::read_radiance(
                    &std::fs::read(dir.join("truth.hdr")).expect("truth.hdr"),
                )
                .expect("read truth.hdr")
                .image;
                assert_eq!((image.width, image.height), (truth.size, truth.size));
                Scene { truth, image }
            })
            .collect(),
    )
}

/// The lens the render was made through (an equidistant fish-eye filling the square), losing
/// half its light at the horizon when `vignetting`.
fn lens(t: &Truth, vignetting: bool) -> LensProfile {
    let half = t.size as f64 / 2.0;
    let mut l = LensProfile::from_fov(
        Circle {
            cx: half,
            cy: half,
            r: half,
        },
        t.fov_deg,
        LensKind::Equidistant,
    )
    .expect("lens");
    if vignetting {
        l.vignetting = Some(Vignetting {
            coefficients: [-0.2, 0.0, 0.0],
            rms: 0.0,
            samples: 0,
        });
    }
    l
}

fn geometry(t: &Truth, vignetting: bool) -> SkyGeometry {
    SkyGeometry::new(
        &lens(t, vignetting),
        0.0,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    )
    .expect("geometry")
}

/// Zenith angle (radians) of a pixel centre of the render.
fn theta(t: &Truth, x: usize, y: usize) -> f64 {
    let half = t.size as f64 / 2.0;
    let r = (x as f64 + 0.5 - half).hypot(y as f64 + 0.5 - half);
    r / half * (t.fov_deg / 2.0).to_radians()
}

/// The settings of the simulated camera (a phone-like sensor, JPEG 95).
fn camera(t: &Truth) -> SynthOptions {
    SynthOptions {
        evs: t.camera.evs.clone(),
        seed: t.camera.seed,
        full_well: 20_000.0,
        read_noise: 2.0,
        jpeg_quality: Some(95),
        ..SynthOptions::default()
    }
}

/// Photographs a scene: the exposure puts the dome's median luminance at 10 % of the full well
/// in the EV 0 frame (a metering camera), shifted by the scene's `ev_offset` stops.
fn photograph(s: &Scene) -> Vec<DecodedFrame> {
    let t = &s.truth;
    let v = lens(t, true).vignetting.expect("vignetting");
    let n = t.size;
    let mut lum: Vec<f64> = (0..n * n)
        .filter(|i| theta(t, i % n, i / n) < std::f64::consts::FRAC_PI_2)
        .map(|i| radiance_luminance(s.image.pixel(i % n, i / n).map(f64::from)))
        .collect();
    let mid = lum.len() / 2;
    let median = *lum.select_nth_unstable_by(mid, f64::total_cmp).1;
    // X = L · Δt · k = L / 4 at EV 0 (synth's convention, base time 1/250 s).
    let scale = 0.4 * t.camera.ev_offset.exp2() / median;
    let mut seen = HdrImage::new(n, n);
    let limit = (t.fov_deg / 2.0).to_radians();
    for y in 0..n {
        for x in 0..n {
            let th = theta(t, x, y);
            let k = if th <= limit { scale * v.at(th) } else { 0.0 };
            let p = s
                .image
                .pixel(x, y)
                .map(|c| (f64::from(c) * 179.0 * k) as f32);
            seen.set_pixel(x, y, p);
        }
    }
    synth::photograph(&seen, &camera(t))
        .expect("photograph")
        .into_iter()
        .map(DecodedFrame::from)
        .collect()
}

/// Pixels clipped (a channel at 255) in the frame nearest EV 0.
fn clipped_in_middle(frames: &[DecodedFrame]) -> usize {
    let mid = &frames[frames.len() / 2];
    let skydome::bracket::Pixels::U8(v) = &mid.pixels else {
        panic!("8-bit")
    };
    v.chunks_exact(3).filter(|p| p.contains(&255)).count()
}

/// The largest code (any channel) within 2 pixels of `sun` in each frame.
fn codes_near(frames: &[DecodedFrame], g: &SkyGeometry, sun: &Direction) -> Vec<u8> {
    let Some(p) = g.direction_to_pixel(sun) else {
        return Vec::new();
    };
    frames
        .iter()
        .map(|f| {
            let skydome::bracket::Pixels::U8(v) = &f.pixels else {
                panic!("8-bit")
            };
            let mut m = 0u8;
            for y in (p.y as i64 - 2).max(0)..=(p.y as i64 + 2).min(f.height as i64 - 1) {
                for x in (p.x as i64 - 2).max(0)..=(p.x as i64 + 2).min(f.width as i64 - 1) {
                    let i = 3 * (y as usize * f.width + x as usize);
                    m = m.max(v[i]).max(v[i + 1]).max(v[i + 2]);
                }
            }
            m
        })
        .collect()
}

/// Horizontal illuminance of the render (lux): what a meter beside the camera reads.
fn truth_illuminance(s: &Scene) -> f64 {
    radiance_luminance(skydome::reproject::horizontal_irradiance_fisheye(
        &s.image,
        &geometry(&s.truth, false),
    ))
}

/// What one scene gave.
#[derive(Debug, Clone)]
struct Score {
    name: String,
    split: String,
    elevation: f64,
    visible: bool,
    /// Partly behind a cloud's edge or an obstacle: not scored unless reported far off.
    partial: bool,
    /// The sun reported, when one was.
    found: Option<Direction>,
    /// Angle between the reported and the true sun, degrees.
    error_deg: Option<f64>,
    /// Reconstructed direct normal / gendaylit's − 1.
    direct_error: Option<f64>,
    /// Reconstructed diffuse horizontal / the render's diffuse − 1.
    diffuse_error: Option<f64>,
    clipped_mid: usize,
    /// The dome's horizontal illuminance (absolute, from the spot reading) / the render's − 1.
    dome_error: f64,
    /// The largest code (any channel) within 2 pixels of the true sun in each frame, shortest
    /// first, and whether the merge flagged the sun's pixel clipped in every frame.
    sun_codes: Vec<u8>,
    warnings: Vec<String>,
}

impl Score {
    /// A sun where none is visible, or far from the visible one.
    fn false_sun(&self) -> bool {
        match (self.visible, self.error_deg) {
            (false, Some(e)) => !self.partial || e > 2.0,
            (true, Some(e)) => e > 2.0,
            _ => false,
        }
    }
}

/// The capture information a station's camera would write (EXIF date, offset and GPS).
fn exif_info(t: &Truth) -> CaptureInfo {
    let mut info = CaptureInfo {
        orientation: 1,
        ..CaptureInfo::default()
    };
    if let (Some(time), Some(lat), Some(lon)) = (&t.time, t.latitude_deg, t.longitude_deg) {
        // "2026-06-21T09:00:00+02:00" → DateTimeOriginal "2026:06:21 09:00:00" + "+02:00".
        let (local, offset) = time.split_at(19);
        info.datetime_original = Some(local.replacen('-', ":", 2).replace('T', " "));
        info.utc_offset = Some(offset.to_string());
        info.gps_latitude_deg = Some(lat);
        info.gps_longitude_deg = Some(lon);
    }
    info
}

/// Photographs and merges one scene with the sun found automatically, and scores it.
fn score(s: &Scene) -> Score {
    let t = &s.truth;
    let truth_sun = Direction::new(t.sun_azimuth_deg, t.sun_elevation_deg);
    let mut frames = photograph(s);
    let clipped_mid = clipped_in_middle(&frames);
    let sun_codes = codes_near(&frames, &geometry(t, false), &truth_sun);
    let info = exif_info(t);
    for f in &mut frames {
        f.info = info.clone();
    }
    // Meter readings: a spot luminance of a sky patch 60° up, 120° round from the sun, and the
    // horizontal illuminance.
    let g = geometry(t, false);
    let spot_dir = Direction::new(t.sun_azimuth_deg + 120.0, 60.0);
    let mut spot = SpotLuminance {
        pixel: g.direction_to_pixel(&spot_dir).expect("spot in view"),
        radius_px: 4.0,
        cd_per_m2: 1.0,
    };
    spot.cd_per_m2 = skydome::photometry::patch_luminance(&s.image, &spot).expect("patch");
    let reading = truth_illuminance(s);
    let o = Options {
        reference: Reference {
            luminance: Some(spot),
            illuminance_lux: Some(reading),
        },
        ..dome_options(t)
    };
    let dome = pipeline::run(
        Input::new(Frames::Decoded(frames)),
        &o,
        &mut pipeline::no_progress,
    )
    .unwrap_or_else(|e| panic!("{}: {e}", t.name));
    let geo = dome.report.geometry.as_ref().expect("geometry");
    let found = geo
        .sun
        .and_then(|m| Some(Direction::new(m.azimuth_deg?, m.elevation_deg?)));
    let error_deg = found.map(|d| d.angle_to(&truth_sun));
    let visible = t.sun_visible;
    let sin_h = t.sun_elevation_deg.to_radians().sin();
    let (direct_error, diffuse_error) = match (&geo.sun_disc, visible) {
        (Some(d), true) => (
            Some(d.direct_normal / t.direct_normal_lux - 1.0),
            Some(d.diffuse_horizontal / (reading - t.direct_normal_lux * sin_h) - 1.0),
        ),
        _ => (None, None),
    };
    Score {
        name: t.name.clone(),
        split: t.split.clone(),
        elevation: t.sun_elevation_deg,
        visible,
        partial: t.sun_partly_hidden,
        found,
        error_deg,
        direct_error,
        diffuse_error,
        clipped_mid,
        dome_error: geo.horizontal_illuminance / reading - 1.0,
        sun_codes,
        warnings: dome.report.warnings.clone(),
    }
}

const BANDS: [(f64, f64); 5] = [
    (0.0, 5.0),
    (5.0, 10.0),
    (10.0, 20.0),
    (20.0, 45.0),
    (45.0, 91.0),
];

/// Prints the table of one split, per elevation band: visible suns found, median and largest
/// angular error, false suns, and the direct and diffuse errors.
fn table(label: &str, scores: &[Score]) {
    eprintln!(
        "{label}: band | visible found/all | error median / max (°) | false suns / scenes | direct normal |err| median / max | diffuse |err| median | dome illuminance |err| max"
    );
    for (lo, hi) in BANDS {
        let band: Vec<&Score> = scores
            .iter()
            .filter(|s| s.elevation >= lo && s.elevation < hi)
            .collect();
        if band.is_empty() {
            continue;
        }
        let vis: Vec<&&Score> = band.iter().filter(|s| s.visible).collect();
        let found = vis.iter().filter(|s| s.found.is_some()).count();
        let mut errs: Vec<f64> = vis.iter().filter_map(|s| s.error_deg).collect();
        errs.sort_by(f64::total_cmp);
        let mut dn: Vec<f64> = vis
            .iter()
            .filter_map(|s| s.direct_error.map(f64::abs))
            .collect();
        dn.sort_by(f64::total_cmp);
        let mut dh: Vec<f64> = vis
            .iter()
            .filter_map(|s| s.diffuse_error.map(f64::abs))
            .collect();
        dh.sort_by(f64::total_cmp);
        let dome = band
            .iter()
            .map(|s| s.dome_error.abs())
            .fold(0.0f64, f64::max);
        let med = |v: &[f64]| v.get(v.len() / 2).copied().unwrap_or(f64::NAN);
        let max = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
        eprintln!(
            "{label}: {lo:>2}–{hi:<2}° | {found}/{} | {:.2} / {:.2} | {} / {} | {:.1} % / {:.1} % | {:.1} % | {:.1} %",
            vis.len(),
            med(&errs),
            max(&errs),
            band.iter().filter(|s| s.false_sun()).count(),
            band.len(),
            100.0 * med(&dn),
            100.0 * max(&dn),
            100.0 * med(&dh),
            100.0 * dome,
        );
    }
}

fn print_scene(s: &Score, t: &Truth) {
    eprintln!(
        "{} [{}] {} (dn {:.0} lx, dh {:.0} lx) {} el {:.1} visible {} partial {} ({:?}) clouds {} obstacles {} frames {} ev {:+}: found {:?} error {:?} dn {:?} dh {:?} dome {:+.1} %; sun codes {:?}; clipped in the middle frame {}; warnings {:?}",
        s.name,
        s.split,
        t.sky,
        t.direct_normal_lux,
        t.diffuse_horizontal_lux,
        t.fov_deg,
        s.elevation,
        s.visible,
        s.partial,
        t.hidden_by,
        t.clouds.len(),
        t.obstacles.len(),
        t.camera.evs.len(),
        t.camera.ev_offset,
        s.found.map(|d| (d.azimuth_deg, d.elevation_deg)),
        s.error_deg,
        s.direct_error,
        s.diffuse_error,
        100.0 * s.dome_error,
        s.sun_codes,
        s.clipped_mid,
        s.warnings
    );
}

/// The case: a sun 10° up at azimuth 250°, direct normal 40 klx, diffuse 9 klx, on a
/// 512² dome whose circumsolar glow clips thousands of pixels of the middle frame. Before issue
/// 22 the detector found no sun (`sun: none`) and the dome lost 46 % of its light.
#[test]
fn low_sun_with_a_large_clipped_aureole_is_found() {
    let Some(scenes) = scenes("issue", "both") else {
        return;
    };
    let s = &scenes[0];
    let sc = score(s);
    print_scene(&sc, &s.truth);
    assert!(
        (5_000..20_000).contains(&sc.clipped_mid),
        "the case needs thousands of clipped circumsolar pixels, has {}",
        sc.clipped_mid
    );
    let err = sc.error_deg.expect("the 10° sun was not found");
    assert!(err < 0.5, "the 10° sun is {err:.2}° off");
    let dn = sc.direct_error.expect("the clipped sun was not rebuilt");
    assert!(dn.abs() < 0.10, "direct normal off by {:.1} %", 100.0 * dn);
}

/// Which sets the sweep tests render and score (`SKYDOME_SUN_SWEEP`): unset (CI), the small
/// `ci` part of the fresh held-out set; `fresh`, all of it; `day`, the station's day; `all`,
/// everything (the benchmark, `scripts/sun_sweep.sh`).
fn sweep_env() -> String {
    std::env::var("SKYDOME_SUN_SWEEP").unwrap_or_default()
}

fn score_all(scenes: &[Scene]) -> Vec<Score> {
    scenes
        .iter()
        .map(|s| {
            let sc = score(s);
            print_scene(&sc, &s.truth);
            sc
        })
        .collect()
}

/// The first sweep (seed 22 split into a tune and a held-out half; the held-out half was looked
/// at while the detector was tuned, so it is no longer held out): scored with
/// `SKYDOME_SUN_SWEEP=all` only, held where the tuning left it.
#[test]
fn tuning_sweep_finds_the_suns_it_was_tuned_on() {
    if sweep_env() != "all" {
        eprintln!(
            "skipping tuning_sweep_finds_the_suns_it_was_tuned_on: set SKYDOME_SUN_SWEEP=all"
        );
        return;
    }
    let Some(scenes) = scenes("sweep", "both") else {
        return;
    };
    let scores = score_all(&scenes);
    for half in ["tune", "held-out"] {
        let part: Vec<Score> = scores.iter().filter(|s| s.split == half).cloned().collect();
        table(half, &part);
    }
    hold_to_targets("sweep (tune + first held-out)", &scores, 0.9, 0.5);
}

/// The fresh held-out set (seed 2211, rendered after the detector was frozen and measured on
/// it untouched; `docs/station.md` has the table): no false sun, every visible sun found within
/// the measured largest error plus a margin, and the measured share of visible suns found. CI
/// renders its `ci` part (six scenes chosen by what they show); `SKYDOME_SUN_SWEEP=fresh` or
/// `all` scores all 30.
#[test]
fn held_out_suns_are_found_and_no_false_one() {
    let set = match sweep_env().as_str() {
        "fresh" | "all" => "fresh",
        _ => "ci",
    };
    let Some(scenes) = scenes(set, "both") else {
        return;
    };
    let scores = score_all(&scenes);
    table(&format!("fresh ({set})"), &scores);
    let label = format!("fresh ({set})");
    hold_to_targets_except(
        &label,
        &scores,
        FRESH_FOUND_MIN,
        FRESH_ERROR_MAX_DEG,
        FRESH_KNOWN_FALSE_SUNS,
    );
    let worst = scores
        .iter()
        .filter_map(|s| s.direct_error.map(|e| (e.abs(), s.name.as_str())))
        .fold((0.0, ""), |a, b| if b.0 > a.0 { b } else { a });
    assert!(
        worst.0 <= FRESH_DIRECT_MAX,
        "{label}: direct normal off by {:.1} % in {}",
        100.0 * worst.0,
        worst.1
    );
    hold_dome(&label, &scores, FRESH_DOME_MAX);
}

/// Every scene's dome horizontal illuminance within `max` of the meter's.
fn hold_dome(label: &str, scores: &[Score], max: f64) {
    let worst = scores
        .iter()
        .map(|s| (s.dome_error.abs(), s.name.as_str()))
        .fold((0.0, ""), |a, b| if b.0 > a.0 { b } else { a });
    assert!(
        worst.0 <= max,
        "{label}: dome illuminance off by {:.1} % in {}",
        100.0 * worst.0,
        worst.1
    );
}

/// The share of visible suns of the `holdout` set (seed 2212) the finder must find: measured
/// 22 of 22, held with a margin of one sun in 20.
const HOLDOUT_FOUND_MIN: f64 = 0.95;

/// The largest |direct normal error| of a rebuilt sun on the `holdout` set: measured 24.0 % (a
/// sun 3–5° up), held at 35 %.
const HOLDOUT_DIRECT_MAX: f64 = 0.35;

/// The largest |dome horizontal illuminance error| on the `holdout` set, against the meter:
/// measured 4.4 %, held at 8 %.
const HOLDOUT_DOME_MAX: f64 = 0.08;

/// The second held-out set (seed 2212, 30 scenes, 2–5 frames; rendered after the finder was
/// frozen again and scored once, untouched; `docs/station.md` has the table): no false sun,
/// every visible sun within 0.5°, the direct part and the dome's illuminance within the
/// measured worst plus a margin. `SKYDOME_SUN_SWEEP=holdout` or `all` (30 renders, too slow
/// for CI).
#[test]
fn second_held_out_set_finds_every_sun_and_no_false_one() {
    if !matches!(sweep_env().as_str(), "holdout" | "all") {
        eprintln!(
            "skipping second_held_out_set_finds_every_sun_and_no_false_one: set SKYDOME_SUN_SWEEP=holdout or all (30 renders, too slow for CI)"
        );
        return;
    }
    let Some(scenes) = scenes("holdout", "both") else {
        return;
    };
    let scores = score_all(&scenes);
    table("holdout", &scores);
    hold_to_targets("holdout", &scores, HOLDOUT_FOUND_MIN, FRESH_ERROR_MAX_DEG);
    let worst = scores
        .iter()
        .filter_map(|s| s.direct_error.map(|e| (e.abs(), s.name.as_str())))
        .fold((0.0, ""), |a, b| if b.0 > a.0 { b } else { a });
    assert!(
        worst.0 <= HOLDOUT_DIRECT_MAX,
        "holdout: direct normal off by {:.1} % in {}",
        100.0 * worst.0,
        worst.1
    );
    hold_dome("holdout", &scores, HOLDOUT_DOME_MAX);
}

/// No false sun, every found sun within `max_error_deg`, and at least `min_found` of the
/// visible suns found.
fn hold_to_targets(label: &str, scores: &[Score], min_found: f64, max_error_deg: f64) {
    hold_to_targets_except(label, scores, min_found, max_error_deg, &[]);
}

/// [`hold_to_targets`], with the false suns of the scenes named in `known_false` (measured and
/// documented failures) printed but not failed.
fn hold_to_targets_except(
    label: &str,
    scores: &[Score],
    min_found: f64,
    max_error_deg: f64,
    known_false: &[&str],
) {
    for s in scores.iter().filter(|s| s.false_sun()) {
        eprintln!("{label}: false sun in {} ({:?}° off)", s.name, s.error_deg);
    }
    let false_suns: Vec<&str> = scores
        .iter()
        .filter(|s| s.false_sun() && !known_false.contains(&s.name.as_str()))
        .map(|s| s.name.as_str())
        .collect();
    assert!(
        false_suns.is_empty(),
        "{label}: false suns in {false_suns:?}"
    );
    let far: Vec<String> = scores
        .iter()
        .filter(|s| s.visible && s.error_deg.is_some_and(|e| e > max_error_deg))
        .map(|s| format!("{} (el {:.1}, {:?}°)", s.name, s.elevation, s.error_deg))
        .collect();
    assert!(
        far.is_empty(),
        "{label}: suns found more than {max_error_deg}° off: {far:?}"
    );
    let visible = scores.iter().filter(|s| s.visible).count();
    let found = scores
        .iter()
        .filter(|s| s.visible && s.found.is_some())
        .count();
    let missed: Vec<String> = scores
        .iter()
        .filter(|s| s.visible && s.found.is_none())
        .map(|s| format!("{} (el {:.1})", s.name, s.elevation))
        .collect();
    eprintln!("{label}: found {found} of {visible} visible suns; missed {missed:?}");
    assert!(
        found as f64 >= min_found * visible as f64,
        "{label}: found {found} of {visible} visible suns; missed {missed:?}"
    );
}

/// One station's day: time and site come from the capture information (EXIF), the sun is
/// found within 0.5° wherever it is visible and never where a cloud or the trees hide it.
#[test]
fn a_stations_day_finds_the_sun_wherever_visible() {
    if !matches!(sweep_env().as_str(), "day" | "all") {
        eprintln!(
            "skipping a_stations_day_finds_the_sun_wherever_visible: set SKYDOME_SUN_SWEEP=day or all (16 renders, too slow for CI)"
        );
        return;
    }
    let Some(scenes) = scenes("day", "both") else {
        return;
    };
    let scores = score_all(&scenes);
    table("day", &scores);
    hold_to_targets("day", &scores, 1.0, 0.5);
}

/// The sweep's dome options (lens with its fall-off, crop, north up, the sun found and a
/// clipped one rebuilt).
fn dome_options(t: &Truth) -> Options {
    Options {
        lens: LensSource::Profile(lens(t, true)),
        sky: SkyOptions {
            crop: true,
            north_deg: Some(0.0),
            sun: SunMode::Auto,
            sun_disc: SunDisc::Reconstruct,
            ..SkyOptions::default()
        },
        ..Options::default()
    }
}
