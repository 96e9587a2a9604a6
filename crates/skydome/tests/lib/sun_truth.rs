//! The clipped sun against Radiance's own skies. `gendaylit` (from the `pyradiance` package on
//! PyPI, found through `SKYDOME_PYTHON`) makes a Perez sky with a sun of known luminance for a
//! given direct-normal and diffuse-horizontal illuminance; `rpict -vta` renders it as an
//! upward 180° angular fish-eye (2048², averaged down to 512² so the 0.53° disc is
//! area-weighted); skydome's camera simulation photographs it through a vignetting lens (EV −2,
//! 0, +2, shot and read noise, JPEG) so that the sun clips in every frame; the pipeline merges
//! it with a spot-luminance reading of a sky patch and the global horizontal illuminance
//! `E_dn · sin h + E_dh`. The reconstructed sun must come out within 10 % of gendaylit's
//! luminance and 0.5° of its direction, the dome's horizontal illuminance within 2 % of the
//! reading, and the sky map close to the render; an overcast sky gets no disc. CI requires the
//! tools (`SKYDOME_REQUIRE_INDEPENDENT_READERS=1`).

use crate::common;
use std::path::Path;
use std::process::Command;

use skydome::bracket::DecodedFrame;
use skydome::fisheye::{LensKind, LensProfile, Vignetting};
use skydome::image::{Circle, HdrImage, PixelPoint};
use skydome::photometry::{Reference, SpotLuminance};
use skydome::pipeline::{self, Frames, Input, LensSource, Options, SkyOptions, SunDisc, SunMode};
use skydome::render::ShIrradiance;
use skydome::reproject::{reproject, MapProjection, ReprojectOptions};
use skydome::sky::{radiance_luminance, Direction};
use skydome::sun_disc::{sun_solid_angle_sr, DirectSource};
use skydome::synth::{self, SynthOptions};

/// A Radiance sky: what gendaylit was told and what it wrote.
struct Sky {
    /// Solar altitude, degrees.
    altitude: f64,
    /// Radiance's solar azimuth: degrees west of south.
    azimuth_west_of_south: f64,
    /// Direct normal illuminance, lux.
    direct_normal: f64,
    /// Diffuse horizontal illuminance, lux.
    diffuse_horizontal: f64,
}

struct Rendered {
    /// Absolute radiance (W·sr⁻¹·m⁻²), 512², upward, north up, east left.
    image: HdrImage,
    /// The sun's luminance as gendaylit states it, cd/m² (0: no sun).
    sun_luminance: f64,
    /// The sun's direction as gendaylit states it.
    sun: Direction,
}

const SIZE: usize = 512;
const FINE: usize = 4;

fn run(bin: &Path, lib: &Path, prog: &str, args: &[&str], dir: &Path) -> Vec<u8> {
    let o = Command::new(bin.join(prog))
        .args(args)
        .current_dir(dir)
        .env("RAYPATH", lib)
        .output()
        .unwrap_or_else(|e| panic!("run {prog}: {e}"));
    assert!(
        o.status.success(),
        "{prog} {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o.stdout
}

/// The numbers following `key` (e.g. "light solar") in a Radiance scene description, after
/// the two empty argument lists.
fn numbers_after(text: &str, key: &str) -> Vec<f64> {
    let at = text
        .find(key)
        .unwrap_or_else(|| panic!("no '{key}' in {text}"));
    let tokens: Vec<&str> = text[at + key.len()..].split_whitespace().collect();
    // "0 0 N a b c …": two empty string/int lists, then N reals.
    let n: usize = tokens[2].parse().expect("count");
    tokens[3..3 + n]
        .iter()
        .map(|t| t.parse().expect("real"))
        .collect()
}

fn render(bin: &Path, lib: &Path, sky: &Sky, dir: &Path) -> Rendered {
    let desc = run(
        bin,
        lib,
        "gendaylit",
        &[
            "-ang",
            &sky.altitude.to_string(),
            &sky.azimuth_west_of_south.to_string(),
            "-L",
            &sky.direct_normal.to_string(),
            &sky.diffuse_horizontal.to_string(),
        ],
        dir,
    );
    let mut text = String::from_utf8(desc).expect("utf-8");
    let solar = numbers_after(&text, "light solar");
    let sun_luminance = radiance_luminance([solar[0], solar[1], solar[2]]);
    let sun = numbers_after(&text, "source sun");
    let sun = Direction::from_vector([sun[0], sun[1], sun[2]]);
    text +=
        "\nskyfunc glow skyglow\n0\n0\n4 1 1 1 0\n\nskyglow source skydome\n0\n0\n4 0 0 1 180\n";
    std::fs::write(dir.join("sky.rad"), text).expect("write sky");
    let oct = run(bin, lib, "oconv", &["sky.rad"], dir);
    std::fs::write(dir.join("sky.oct"), oct).expect("write octree");
    let n = (SIZE * FINE).to_string();
    let hdr = run(
        bin,
        lib,
        "rpict",
        &[
            "-vta", "-vp", "0", "0", "0", "-vd", "0", "0", "1", "-vu", "0", "1", "0", "-vh", "180",
            "-vv", "180", "-x", &n, "-y", &n, "-ps", "1", "-pj", "0", "-ab", "0", "sky.oct",
        ],
        dir,
    );
    let fine = skydome::formats::read_radiance(&hdr)
        .expect("read rpict's picture")
        .image;
    assert_eq!((fine.width, fine.height), (SIZE * FINE, SIZE * FINE));
    // Box-average FINE × FINE: the sun's disc (6 fine pixels wide) becomes area-weighted.
    let mut image = HdrImage::new(SIZE, SIZE);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let mut acc = [0.0f64; 3];
            for j in 0..FINE {
                for i in 0..FINE {
                    let p = fine.pixel(FINE * x + i, FINE * y + j);
                    for c in 0..3 {
                        acc[c] += f64::from(p[c]);
                    }
                }
            }
            let k = (FINE * FINE) as f64;
            image.set_pixel(x, y, acc.map(|v| (v / k) as f32));
        }
    }
    Rendered {
        image,
        sun_luminance,
        sun,
    }
}

fn lens() -> LensProfile {
    let half = SIZE as f64 / 2.0;
    let mut l = LensProfile::from_fov(
        Circle {
            cx: half,
            cy: half,
            r: half,
        },
        180.0,
        LensKind::Equidistant,
    )
    .expect("lens");
    // Half the light is lost at the horizon: V(θ) = 1 − 0.2 θ².
    l.vignetting = Some(Vignetting {
        coefficients: [-0.2, 0.0, 0.0],
        rms: 0.0,
        samples: 0,
    });
    l
}

/// The zenith angle (radians) of a pixel centre in the 512² render.
fn theta(x: usize, y: usize) -> f64 {
    let half = SIZE as f64 / 2.0;
    let r = (x as f64 + 0.5 - half).hypot(y as f64 + 0.5 - half);
    r / half * std::f64::consts::FRAC_PI_2
}

/// Photographs the render through the vignetting lens: scaled so that the brightest sky (99th
/// percentile of the luminance away from the sun) fills half the well in the shortest frame.
fn photograph(r: &Rendered) -> Vec<DecodedFrame> {
    let v = lens().vignetting.expect("vignetting");
    let mut lum: Vec<f64> = (0..SIZE * SIZE)
        .filter(|i| theta(i % SIZE, i / SIZE) < 1.5)
        .map(|i| radiance_luminance(r.image.pixel(i % SIZE, i / SIZE).map(f64::from)))
        .filter(|l| *l > 0.0)
        .collect();
    lum.sort_by(f64::total_cmp);
    let p99 = lum[lum.len() * 99 / 100];
    let opts = SynthOptions {
        full_well: 20_000.0,
        read_noise: 2.0,
        jpeg_quality: Some(95),
        ..SynthOptions::default()
    };
    // Luminance p99 → X = 0.5 at EV −2 (X = L · Δt · k = L / 16 there).
    let scale = 8.0 / p99;
    let mut seen = HdrImage::new(SIZE, SIZE);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let t = theta(x, y);
            let k = if t <= std::f64::consts::FRAC_PI_2 {
                scale * v.at(t)
            } else {
                0.0
            };
            let p = r
                .image
                .pixel(x, y)
                .map(|c| (f64::from(c) * 179.0 * k) as f32);
            seen.set_pixel(x, y, p);
        }
    }
    synth::photograph(&seen, &opts)
        .expect("photograph")
        .into_iter()
        .map(DecodedFrame::from)
        .collect()
}

struct Outcome {
    dome: pipeline::Dome,
    reading_lux: f64,
}

fn merge(r: &Rendered, sky: &Sky, sun_disc: SunDisc) -> Outcome {
    // A spot reading of a sky patch 90° round from the sun, 40° up.
    let patch = skydome::fisheye::LensProfile::clone(&lens());
    let g = skydome::sky::SkyGeometry::new(
        &patch,
        0.0,
        skydome::sky::DevicePose::ScreenDown,
        skydome::sky::ImageOrientation::Normal,
    )
    .expect("geometry");
    let spot_dir = Direction::new(r.sun.azimuth_deg + 90.0, 40.0);
    let spot_px = g.direction_to_pixel(&spot_dir).expect("spot in view");
    let radius = 6.0;
    let mut spot = SpotLuminance {
        pixel: spot_px,
        radius_px: radius,
        cd_per_m2: 1.0,
    };
    spot.cd_per_m2 = skydome::photometry::patch_luminance(&r.image, &spot).expect("patch");
    let reading_lux = sky.direct_normal * sky.altitude.to_radians().sin() + sky.diffuse_horizontal;
    let o = Options {
        lens: LensSource::Profile(lens()),
        sky: SkyOptions {
            crop: true,
            north_deg: Some(0.0),
            sun: SunMode::Auto,
            sun_disc,
            ..SkyOptions::default()
        },
        reference: Reference {
            luminance: Some(spot),
            illuminance_lux: Some(reading_lux),
        },
        products: pipeline::Products {
            equirect: Some(pipeline::EquirectOptions::default()),
            ..pipeline::Products::default()
        },
        ..Options::default()
    };
    let input = Input::new(Frames::Decoded(photograph(r)));
    let dome = pipeline::run(input, &o, &mut pipeline::no_progress).expect("merge");
    Outcome { dome, reading_lux }
}

/// Median and 95th percentile of |L/L_true − 1| inside 85° of the zenith and beyond 5° of the
/// sun (the clipped aureole is a lower bound by design).
fn map_error(out: &Outcome, truth: &Rendered) -> (f64, f64) {
    let g = out.dome.report.geometry.as_ref().expect("geometry");
    let img = &out.dome.radiance;
    let sun = truth.sun.to_vector();
    let tg = skydome::sky::SkyGeometry::new(
        &lens(),
        0.0,
        skydome::sky::DevicePose::ScreenDown,
        skydome::sky::ImageOrientation::Normal,
    )
    .expect("geometry");
    let mut errs = Vec::new();
    for y in 0..img.height {
        for x in 0..img.width {
            let p = PixelPoint {
                x: x as f64 + 0.5,
                y: y as f64 + 0.5,
            };
            let Some(q) = g.input_pixel(p) else { continue };
            let (tx, ty) = (q.x.floor() as usize, q.y.floor() as usize);
            if tx >= SIZE || ty >= SIZE || theta(tx, ty) > 85f64.to_radians() {
                continue;
            }
            let Some(v) = tg.pixel_to_vector(q.x, q.y) else {
                continue;
            };
            let cos = v[0] * sun[0] + v[1] * sun[1] + v[2] * sun[2];
            if truth.sun_luminance > 0.0 && cos > 5f64.to_radians().cos() {
                continue;
            }
            let want = radiance_luminance(truth.image.pixel(tx, ty).map(f64::from));
            let got = radiance_luminance(img.pixel(x, y).map(f64::from));
            errs.push((got / want - 1.0).abs());
        }
    }
    errs.sort_by(f64::total_cmp);
    (errs[errs.len() / 2], errs[errs.len() * 95 / 100])
}

/// What the lit spheres' diffuse sphere shows (the order-2 SH irradiance `skydome render`
/// shades it with), luminance units: on its side facing the sun, and on its side facing away
/// from the sun's azimuth at the horizon (in the sun's shadow).
fn lit_and_shadow(equirect: &HdrImage, sun: &Direction) -> (f64, f64) {
    let sh = ShIrradiance::from_equirect(equirect).expect("SH");
    let lit = radiance_luminance(sh.irradiance(sun.to_vector()));
    let away = Direction::new(sun.azimuth_deg + 180.0, 0.0);
    let shadow = radiance_luminance(sh.irradiance(away.to_vector()));
    (lit, shadow)
}

/// The truth's equirectangular map, as `merge --equirect` lays it out.
fn truth_equirect(truth: &Rendered, width: usize) -> HdrImage {
    let g = skydome::sky::SkyGeometry::new(
        &LensProfile {
            vignetting: None,
            ..lens()
        },
        0.0,
        skydome::sky::DevicePose::ScreenDown,
        skydome::sky::ImageOrientation::Normal,
    )
    .expect("geometry");
    reproject(
        &truth.image,
        &g,
        &MapProjection::Equirect {
            width,
            centre_azimuth_deg: 90.0,
        },
        &ReprojectOptions::default(),
    )
    .expect("reproject")
}

#[test]
fn reconstructed_suns_match_radiance_skies() {
    let Some((bin, lib)) = common::radiance_tools() else {
        return;
    };
    let skies = [
        (
            "high sun",
            Sky {
                altitude: 60.0,
                azimuth_west_of_south: 30.0,
                direct_normal: 85_000.0,
                diffuse_horizontal: 14_000.0,
            },
        ),
        (
            "low sun",
            Sky {
                altitude: 10.0,
                azimuth_west_of_south: -70.0,
                direct_normal: 30_000.0,
                diffuse_horizontal: 9_000.0,
            },
        ),
        (
            "overcast",
            Sky {
                altitude: 35.0,
                azimuth_west_of_south: 10.0,
                direct_normal: 0.0,
                diffuse_horizontal: 18_000.0,
            },
        ),
    ];
    for (name, sky) in &skies {
        let dir = tempfile::tempdir().expect("tempdir");
        let truth = render(&bin, &lib, sky, dir.path());
        let out = merge(&truth, sky, SunDisc::Reconstruct);
        let g = out.dome.report.geometry.as_ref().expect("geometry");
        let e = g.horizontal_illuminance;
        let (median, p95) = map_error(&out, &truth);
        eprintln!(
            "{name}: dome {e:.0} lx vs reading {:.0} lx; sky map error median {:.1} % p95 {:.1} %; disc {:?}; warnings {:?}",
            out.reading_lux,
            100.0 * median,
            100.0 * p95,
            g.sun_disc,
            out.dome.report.warnings
        );
        assert!(median < 0.05, "{name}: median {median}");
        assert!(p95 < 0.15, "{name}: p95 {p95}");
        if truth.sun_luminance == 0.0 {
            // Nothing clipped, nothing invented.
            assert!(g.sun_disc.is_none(), "{name}: {:?}", g.sun_disc);
            assert!(!out
                .dome
                .meta
                .other
                .iter()
                .any(|l| l.starts_with("#SUN_DISC")));
            assert!((e / out.reading_lux - 1.0).abs() < 0.05, "{name}: {e}");
            continue;
        }
        let disc = g
            .sun_disc
            .unwrap_or_else(|| panic!("{name}: the clipped sun was not rebuilt"));
        assert_eq!(disc.from, DirectSource::MeasuredIlluminance);
        assert!(disc.absolute);
        assert!(
            (e / out.reading_lux - 1.0).abs() < 0.02,
            "{name}: dome {e} lx vs {}",
            out.reading_lux
        );
        let dl = disc.luminance / truth.sun_luminance - 1.0;
        assert!(
            dl.abs() < 0.10,
            "{name}: sun {} vs {} cd/m²",
            disc.luminance,
            truth.sun_luminance
        );
        let off = disc.direction.angle_to(&truth.sun);
        assert!(off < 0.5, "{name}: sun {off}° off");
        // The direct normal it implies is the one gendaylit was given.
        let dn = disc.luminance * sun_solid_angle_sr();
        assert!((dn / sky.direct_normal - 1.0).abs() < 0.10, "{name}: {dn}");
        assert!(out
            .dome
            .meta
            .other
            .iter()
            .any(|l| l.starts_with("#SUN_DISC= reconstructed")));

        // Kept, the clipped sun is far too dim: the point of the reconstruction.
        let kept = merge(&truth, sky, SunDisc::Keep);
        let gk = kept.dome.report.geometry.as_ref().expect("geometry");
        assert!(gk.sun_disc.is_none());
        assert!(gk.horizontal_illuminance < 0.9 * out.reading_lux, "{name}");

        // The lit spheres: the diffuse sphere's sunny and shadowed sides as the truth's.
        let ours_map = &out.dome.equirect.as_ref().expect("equirect").0;
        let kept_map = &kept.dome.equirect.as_ref().expect("equirect").0;
        let truth_map = truth_equirect(&truth, ours_map.width);
        let (lit_t, shadow_t) = lit_and_shadow(&truth_map, &truth.sun);
        let (lit_o, shadow_o) = lit_and_shadow(ours_map, &truth.sun);
        let (lit_k, shadow_k) = lit_and_shadow(kept_map, &truth.sun);
        eprintln!(
            "{name}: diffuse sphere lit/shadow side, truth {lit_t:.0}/{shadow_t:.0} = {:.2}, rebuilt {lit_o:.0}/{shadow_o:.0} = {:.2}, kept {lit_k:.0}/{shadow_k:.0} = {:.2}",
            lit_t / shadow_t,
            lit_o / shadow_o,
            lit_k / shadow_k
        );
        assert!(
            (lit_o / lit_t - 1.0).abs() < 0.10,
            "{name}: lit {lit_o} vs {lit_t}"
        );
        assert!(
            (shadow_o / shadow_t - 1.0).abs() < 0.15,
            "{name}: shadow {shadow_o} vs {shadow_t}"
        );
        let (ratio_o, ratio_t) = (lit_o / shadow_o, lit_t / shadow_t);
        assert!(
            (ratio_o / ratio_t - 1.0).abs() < 0.15,
            "{name}: {ratio_o} vs {ratio_t}"
        );
        assert!(
            lit_k / shadow_k < 0.6 * ratio_t,
            "{name}: a kept sun casts a shadow?"
        );
    }
}
