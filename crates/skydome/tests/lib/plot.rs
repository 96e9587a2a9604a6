//! Pictures: response curves (PNG/SVG), false colour, histogram, and one saved picture of each
//! kind (plus the tone-mapped preview and the lit spheres) under `target/pictures/` to look at,
//! each compared with its reference picture in `tests/reference/` (`SKYDOME_BLESS=1` rewrites them).

use std::path::PathBuf;

use skydome::image::{Circle, HdrImage};
use skydome::plot::{
    encode_png_rgb16, encode_png_rgb8, false_colour, false_colour_ramp,
    log_luminance_histogram_png, response_curves_png, response_curves_svg, FalseColour, PlotError,
};
use skydome::render::{equirect_uv_to_direction, render_spheres, SphereScene};
use skydome::tonemap::{luminance_stats, tonemap_u16, tonemap_u8, ToneMap};

fn pictures_dir() -> PathBuf {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/pictures");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A pixel differs when one of its channels differs by more than this many 8-bit codes …
const REFERENCE_CODES: i32 = 8;
/// … and a picture matches its reference when at most this fraction of its pixels differ
/// (room for another CPU's rounding in anti-aliased edges and glyphs, none for a moved curve,
/// a lost label or a changed colour map).
const REFERENCE_PIXELS: f64 = 0.01;

/// Compares the PNG `png` with `tests/reference/<name>.png` within the tolerance above, or
/// writes it there when `SKYDOME_BLESS=1` (then look at it before committing it). A picture
/// that does not match is also written to `target/pictures/<name>.actual.png`.
fn check_reference(name: &str, png: &[u8]) {
    let reference = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/reference")
        .join(format!("{name}.png"));
    if std::env::var("SKYDOME_BLESS").as_deref() == Ok("1") {
        std::fs::create_dir_all(reference.parent().unwrap()).unwrap();
        let tmp = reference.with_extension("png.tmp");
        std::fs::write(&tmp, png).unwrap();
        std::fs::rename(&tmp, &reference).unwrap();
        return;
    }
    let got = image::load_from_memory(png).unwrap().into_rgb8();
    let want = image::open(&reference)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (SKYDOME_BLESS=1 cargo test -p skydome --test lib plot:: writes it)",
                reference.display()
            )
        })
        .into_rgb8();
    let actual = pictures_dir().join(format!("{name}.actual.png"));
    if got.dimensions() != want.dimensions() {
        std::fs::write(&actual, png).unwrap();
        panic!(
            "{name}: {:?} pixels, the reference has {:?} (see {})",
            got.dimensions(),
            want.dimensions(),
            actual.display()
        );
    }
    let differ = got
        .pixels()
        .zip(want.pixels())
        .filter(|(a, b)| (0..3).any(|c| (a[c] as i32 - b[c] as i32).abs() > REFERENCE_CODES))
        .count();
    let fraction = differ as f64 / (got.width() as f64 * got.height() as f64);
    if fraction > REFERENCE_PIXELS {
        std::fs::write(&actual, png).unwrap();
        panic!(
            "{name}: {:.2} % of the pixels differ from {} by more than {REFERENCE_CODES} codes \
             (at most {:.0} % may; see {}; SKYDOME_BLESS=1 rewrites the reference)",
            100.0 * fraction,
            reference.display(),
            100.0 * REFERENCE_PIXELS,
            actual.display()
        );
    }
}

/// A 2:1 lat-long sky: blue gradient, soft clouds, a 1° sun 2^17 × the sky median at azimuth
/// 200°, elevation 40°; black below the horizon.
fn synthetic_sky(w: usize) -> HdrImage {
    let h = w / 2;
    let mut img = HdrImage::new(w, h);
    let sun = equirect_uv_to_direction(200.0 / 360.0, 0.5 - 40.0 / 180.0);
    for y in 0..h / 2 {
        for x in 0..w {
            let d =
                equirect_uv_to_direction((x as f64 + 0.5) / w as f64, (y as f64 + 0.5) / h as f64);
            let el = d[2].asin() as f32;
            let az = 2.0 * std::f32::consts::PI * (x as f32 + 0.5) / w as f32;
            let t = 1.0 - el / std::f32::consts::FRAC_PI_2;
            let cos_sun = (d[0] * sun[0] + d[1] * sun[1] + d[2] * sun[2]) as f32;
            // Brighter circumsolar sky, like a real clear sky.
            let glow = 1.0 + 2.0 * cos_sun.max(0.0).powi(8);
            let mut rgb = [
                (0.25 + 0.35 * t) * glow,
                (0.4 + 0.3 * t) * glow,
                (0.9 + 0.1 * t) * glow,
            ];
            let cloud = (-((az - 1.2).powi(2) / 0.05 + (el - 0.5).powi(2) / 0.02)).exp()
                + (-((az - 4.5).powi(2) / 0.1 + (el - 0.25).powi(2) / 0.01)).exp();
            for c in &mut rgb {
                *c = *c * (1.0 - 0.6 * cloud) + 1.4 * cloud;
            }
            if cos_sun > 1f32.to_radians().cos() {
                let s = 131_072.0 * 0.45;
                rgb = [s, s * 0.97, s * 0.9];
            }
            img.set_pixel(x, y, rgb);
        }
    }
    img
}

/// A 180° equidistant fish-eye view of the same sky, north up and east on the left (camera
/// looking up), black outside the circle.
fn fisheye_of(sky: &HdrImage, size: usize) -> (HdrImage, Circle) {
    let mut img = HdrImage::new(size, size);
    let c = Circle {
        cx: size as f64 / 2.0,
        cy: size as f64 / 2.0,
        r: size as f64 / 2.0 - 2.0,
    };
    for y in 0..size {
        for x in 0..size {
            let dx = x as f64 + 0.5 - c.cx;
            let dy = y as f64 + 0.5 - c.cy;
            let r = (dx * dx + dy * dy).sqrt() / c.r;
            if r > 1.0 {
                continue;
            }
            let zen = r * std::f64::consts::FRAC_PI_2;
            // North up, east left: azimuth grows counter-clockwise from the top.
            let az = (-dx).atan2(-dy);
            let d = [zen.sin() * az.sin(), zen.sin() * az.cos(), zen.cos()];
            img.set_pixel(x, y, skydome::render::sample_equirect(sky, d));
        }
    }
    (img, c)
}

/// Response curves of a camera with `Z = 255 (X / X_c)^(1/2.2)`, so `g(Z) = 2.2 ln(Z/255) +
/// ln X_c`, and samples from three exposures.
/// Per-channel `g(Z)` curves and `(ln E·Δt, Z)` samples.
type ResponseData = ([Vec<f64>; 3], [Vec<(f64, u8)>; 3]);

fn synthetic_response() -> ResponseData {
    let lnx = [0.3f64, 0.0, -0.4];
    let curves = lnx.map(|c| {
        (0..256)
            .map(|z| 2.2 * ((z as f64 + 0.5) / 256.0).ln() + c)
            .collect::<Vec<f64>>()
    });
    let mut samples: [Vec<(f64, u8)>; 3] = Default::default();
    let mut seed = 12345u64;
    for (c, s) in samples.iter_mut().enumerate() {
        for i in 0..120 {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let ln_e = -6.0 + 6.0 * (seed >> 11) as f64 / (1u64 << 53) as f64;
            for ln_dt in [-2.079, 0.0, 2.079] {
                let x = ln_e + ln_dt;
                let z = 256.0 * ((x - lnx[c]) / 2.2).exp() - 0.5;
                let noise = ((i * 7 + c * 3) % 5) as f64 - 2.0;
                if (1.0..255.0).contains(&z) {
                    s.push((x, (z + noise).clamp(0.0, 255.0) as u8));
                }
            }
        }
    }
    (curves, samples)
}

#[test]
fn response_curves_render_as_png_and_svg_with_labels() {
    let (curves, samples) = synthetic_response();
    let s = [&samples[0][..], &samples[1][..], &samples[2][..]];
    let png = response_curves_png(&curves, s, (900, 650)).unwrap();
    let img = image::load_from_memory(&png).unwrap().into_rgb8();
    assert_eq!(img.dimensions(), (900, 650));
    // Each channel colour appears (the curves), and text pixels (dark grey) too.
    let count = |f: &dyn Fn(&image::Rgb<u8>) -> bool| img.pixels().filter(|p| f(p)).count();
    assert!(
        count(&|p| p[0] > 150 && p[1] < 80 && p[2] < 80) > 500,
        "red curve"
    );
    assert!(
        count(&|p| p[1] > 110 && p[0] < 60 && p[2] < 90) > 500,
        "green curve"
    );
    assert!(
        count(&|p| p[2] > 160 && p[0] < 80 && p[1] < 110) > 500,
        "blue curve"
    );
    assert!(
        count(&|p| p[0] < 60 && p[1] < 60 && p[2] < 60) > 2000,
        "axes and text"
    );
    std::fs::write(pictures_dir().join("response_curves.png"), &png).unwrap();
    check_reference("response_curves", &png);
    let svg = response_curves_svg(&curves, s, (900, 650)).unwrap();
    assert!(svg.starts_with("<svg"));
    for label in ["log exposure", "pixel value", "red", "green", "blue"] {
        assert!(svg.contains(label), "SVG lacks '{label}'");
    }
    std::fs::write(pictures_dir().join("response_curves.svg"), &svg).unwrap();
}

#[test]
fn response_plot_rejects_short_or_non_finite_curves() {
    let (mut curves, samples) = synthetic_response();
    let s = [&samples[0][..], &samples[1][..], &samples[2][..]];
    curves[1][10] = f64::NAN;
    assert!(matches!(
        response_curves_png(&curves, s, (800, 600)),
        Err(PlotError::BadCurve { channel: 1, .. })
    ));
    curves[1] = vec![0.0; 100];
    assert!(matches!(
        response_curves_svg(&curves, s, (800, 600)),
        Err(PlotError::BadCurve {
            channel: 1,
            len: 100,
            ..
        })
    ));
    let (curves, _) = synthetic_response();
    assert!(matches!(
        response_curves_png(&curves, s, (10, 600)),
        Err(PlotError::BadSize { .. })
    ));
}

#[test]
fn false_colour_maps_luminance_decades_to_the_ramp_and_keeps_masked_pixels_black() {
    // A row of luminance 10^-1 … 10^2 inside a circle.
    let (w, h) = (400, 300);
    let mut img = HdrImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let v = 10f32.powf(-1.0 + 3.0 * x as f32 / (w - 1) as f32);
            img.set_pixel(x, y, [v, v, v]);
        }
    }
    let mask = Circle {
        cx: 200.0,
        cy: 150.0,
        r: 140.0,
    };
    let opts = FalseColour {
        mask: Some(mask),
        range: Some((0.1, 100.0)),
        ..FalseColour::default()
    };
    let out = false_colour(&img, &opts).unwrap();
    assert_eq!(out.width, w + opts.bar_width);
    for x in [70usize, 133, 200, 266, 330] {
        let v = 10f64.powf(-1.0 + 3.0 * x as f64 / (w - 1) as f64);
        let t = (v.log10() + 1.0) / 3.0;
        let want = false_colour_ramp(t);
        let got = out.pixel(x, 150);
        for c in 0..3 {
            assert!(
                (got[c] as i32 - want[c] as i32).abs() <= 1,
                "x={x}: {got:?} vs {want:?}"
            );
        }
    }
    assert_eq!(out.pixel(5, 5), [0; 3], "outside the mask");
    // Absolute units: the same picture with scale 1000 and a range 1000× higher is identical.
    let abs = false_colour(
        &img,
        &FalseColour {
            scale: Some(1000.0),
            range: Some((100.0, 100_000.0)),
            bar_width: 0,
            ..opts
        },
    )
    .unwrap();
    for x in 0..w {
        assert_eq!(abs.pixel(x, 150), out.pixel(x, 150));
    }
    assert!(false_colour(
        &img,
        &FalseColour {
            range: Some((10.0, 1.0)),
            ..opts
        }
    )
    .is_err());
}

#[test]
fn pictures_of_every_kind_match_their_reference_pictures() {
    let sky = synthetic_sky(1024);
    let (fish, circle) = fisheye_of(&sky, 600);
    let dir = pictures_dir();
    // Written under target/pictures/ to look at, and compared with its reference picture.
    let keep = |name: &str, png: &[u8]| {
        std::fs::write(dir.join(format!("{name}.png")), png).unwrap();
        check_reference(name, png);
    };

    // Tone-mapped previews of the fish-eye dome, every operator.
    for op in skydome::tonemap::Operator::NAMES {
        let tm = ToneMap {
            mask: Some(circle),
            ..ToneMap::with_operator(op.parse().unwrap())
        };
        let out = tonemap_u8(&fish, &tm).unwrap();
        keep(&format!("preview_{op}"), &encode_png_rgb8(&out).unwrap());
    }
    let out16 = tonemap_u16(&fish, &ToneMap::default()).unwrap();
    let png16 = encode_png_rgb16(&out16).unwrap();
    let back = image::load_from_memory(&png16).unwrap().into_rgb16();
    assert!(
        back.as_raw() == &out16.data,
        "16-bit PNG does not round-trip"
    );
    keep("preview_aces_16bit", &png16);

    // False colour, relative and in cd/m² (pretend 1 unit = 2000 cd/m²).
    let fc = false_colour(
        &fish,
        &FalseColour {
            mask: Some(circle),
            ..FalseColour::default()
        },
    )
    .unwrap();
    keep("false_colour", &encode_png_rgb8(&fc).unwrap());
    let fc_abs = false_colour(
        &fish,
        &FalseColour {
            mask: Some(circle),
            scale: Some(2000.0),
            ..FalseColour::default()
        },
    )
    .unwrap();
    keep("false_colour_cdm2", &encode_png_rgb8(&fc_abs).unwrap());

    // Histogram.
    let hist = log_luminance_histogram_png(&fish, Some(&circle), (900, 500)).unwrap();
    let st = luminance_stats(&fish, Some(&circle)).unwrap();
    println!(
        "fish-eye sky: dynamic range {:.1} stops, 0.1–99.9 %: {:.1} stops",
        st.dynamic_range_stops(),
        st.robust_range_stops(0.1, 99.9)
    );
    assert!(st.dynamic_range_stops() > 17.0);
    keep("histogram", &hist);

    // Lit spheres, camera facing north with the sun behind it (south-south-west).
    let spheres = render_spheres(&sky, &SphereScene::default(), &ToneMap::default()).unwrap();
    let mean: f64 = spheres.data.iter().map(|v| *v as f64).sum::<f64>() / spheres.data.len() as f64;
    assert!(mean > 30.0);
    keep("spheres", &encode_png_rgb8(&spheres).unwrap());
    // Camera facing the sun: back-lit spheres, shadows towards the camera.
    let back_lit = render_spheres(
        &sky,
        &SphereScene {
            view_azimuth_deg: 160.0,
            ..SphereScene::default()
        },
        &ToneMap::default(),
    )
    .unwrap();
    keep("spheres_backlit", &encode_png_rgb8(&back_lit).unwrap());
    // The sky itself, lat-long.
    let ll = tonemap_u8(&sky, &ToneMap::default()).unwrap();
    keep("sky_latlong", &encode_png_rgb8(&ll).unwrap());
}
