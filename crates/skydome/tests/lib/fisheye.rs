//! Lens models, fits, profiles, circle detection and the dome crop, on synthetic ground truth
//! and on the real Alpnach all-sky frames.

use crate::fisheye_support::*;
use skydome::fisheye::*;
use skydome::image::Circle;

const KINDS: [LensKind; 4] = [
    LensKind::Equidistant,
    LensKind::Equisolid,
    LensKind::Stereographic,
    LensKind::Orthographic,
];

#[test]
fn projection_inverse_round_trips_every_model() {
    let models = [
        Projection::Equidistant { f_px: 300.0 },
        Projection::Equisolid { f_px: 300.0 },
        Projection::Stereographic { f_px: 300.0 },
        Projection::Orthographic { f_px: 300.0 },
        Projection::Polynomial {
            k1: 300.0,
            k3: -12.0,
            k5: 1.5,
        },
    ];
    for p in models {
        let limit = p.theta_limit().min(2.9);
        for i in 0..=200 {
            let t = limit * i as f64 / 200.0;
            let back = p
                .theta(p.radius(t))
                .expect("inverse exists inside the limit");
            assert!((back - t).abs() < 1e-9, "{p:?}: θ {t} → {back}");
        }
        // Beyond the largest radius there is no ray.
        if p.kind() == LensKind::Orthographic || p.kind() == LensKind::Equisolid {
            assert!(p.theta(p.radius(p.theta_limit()) + 1.0).is_none());
        }
    }
}

#[test]
fn horizon_sits_at_061_077_083_of_a_235_degree_circle() {
    let circle = Circle {
        cx: 500.0,
        cy: 400.0,
        r: 380.0,
    };
    let expect = [
        (
            LensKind::Stereographic,
            0.61,
            45f64.to_radians().tan() / 58.75f64.to_radians().tan(),
        ),
        (LensKind::Equidistant, 0.77, 90.0 / 117.5),
        (
            LensKind::Equisolid,
            0.83,
            45f64.to_radians().sin() / 58.75f64.to_radians().sin(),
        ),
    ];
    for (kind, rounded, exact) in expect {
        let lens = LensProfile::from_fov(circle, 235.0, kind).unwrap();
        let ratio = lens.radius_at_deg(90.0).unwrap() / circle.r;
        assert!((ratio - exact).abs() < 1e-12, "{kind}: {ratio} vs {exact}");
        assert!(
            (ratio - rounded).abs() < 0.005,
            "{kind}: {ratio} rounds to {rounded}"
        );
    }
    // Orthographic cannot see beyond 90°: a 235° fisheye is not orthographic.
    assert!(LensProfile::from_fov(circle, 235.0, LensKind::Orthographic).is_err());
}

#[test]
fn crop_radius_is_exact_and_everything_beyond_the_horizon_is_zero() {
    for kind in [
        LensKind::Stereographic,
        LensKind::Equidistant,
        LensKind::Equisolid,
    ] {
        let dome = Dome {
            width: 420,
            height: 360,
            cx: 211.3,
            cy: 178.8,
            lens: Lens::for_circle(kind.name(), 235.0, 160.0),
            visible_r: 160.0,
            north_deg: 0.0,
            housing: 0.0,
            ss: 1,
        };
        let img = dome.render(&|_, el| [1.0 + el as f32, 2.0, 3.0]);
        let lens = LensProfile::from_fov(
            Circle {
                cx: dome.cx,
                cy: dome.cy,
                r: 160.0,
            },
            235.0,
            kind,
        )
        .unwrap();
        let crop = crop_dome(&img, &lens, 180.0).unwrap();
        let r90 = dome.lens.r(std::f64::consts::FRAC_PI_2);
        assert!(
            (crop.crop_radius_px - r90).abs() < 1e-9,
            "{kind}: {} vs {r90}",
            crop.crop_radius_px
        );
        let n = crop.image.width;
        assert_eq!(n, crop.image.height);
        assert!((crop.horizon.cx - n as f64 / 2.0).abs() <= 0.5);
        assert!((crop.horizon.cy - n as f64 / 2.0).abs() <= 0.5);
        assert!(crop.horizon.cx + r90 <= n as f64 && crop.horizon.cx - r90 >= 0.0);
        for y in 0..n {
            for x in 0..n {
                let p = crop.image.pixel(x, y);
                if crop.horizon.contains_pixel(x, y) {
                    let sx = (x as i64 + crop.offset_x) as usize;
                    let sy = (y as i64 + crop.offset_y) as usize;
                    assert_eq!(p, img.pixel(sx, sy), "copied verbatim");
                } else {
                    assert_eq!(p, [0.0; 3], "masked beyond 90° at ({x},{y})");
                }
            }
        }
    }
}

/// The owned crop (the pipeline's: the merged square itself, zeroed beyond the circle where it
/// lies) gives the copying crop's result bit for bit, on the crop's own square (in place, the
/// same buffer kept) and on any other part of the frame (copied).
#[test]
fn owned_crop_equals_the_copy_in_place_or_not() {
    let dome = Dome {
        width: 420,
        height: 360,
        cx: 211.3,
        cy: 178.8,
        lens: Lens::for_circle("stereographic", 235.0, 160.0),
        visible_r: 160.0,
        north_deg: 0.0,
        housing: 0.0,
        ss: 1,
    };
    // Values that differ everywhere, a negative zero and a NaN inside the circle: copied as
    // they are either way.
    let mut img = dome.render(&|az, el| [1.0 + el as f32, 2.0 + az as f32, 3.0]);
    let c = 3 * (179 * img.width + 211);
    img.data[c] = -0.0;
    img.data[c + 1] = f32::NAN;
    let lens = LensProfile::from_fov(
        Circle {
            cx: dome.cx,
            cy: dome.cy,
            r: 160.0,
        },
        235.0,
        LensKind::Stereographic,
    )
    .unwrap();
    let bits = |c: &DomeCrop| c.image.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let want = crop_dome(&img, &lens, 180.0).unwrap();
    assert!(want.image.data.contains(&0.0) && want.image.data.iter().any(|v| *v > 0.0));
    // The crop's square alone, as the pipeline merges it.
    let (ox, oy, n, _) = dome_crop_box(&lens, 180.0).unwrap();
    assert!(ox >= 0 && oy >= 0 && ox as usize + n <= img.width && oy as usize + n <= img.height);
    let mut square = skydome::image::HdrImage::new(n, n);
    for y in 0..n {
        let s = 3 * ((oy as usize + y) * img.width + ox as usize);
        square.data[3 * y * n..3 * (y + 1) * n].copy_from_slice(&img.data[s..s + 3 * n]);
    }
    let before = square.data.as_ptr();
    let got = crop_dome_owned(square, (ox, oy), &lens, 180.0).unwrap();
    assert_eq!(got.image.data.as_ptr(), before, "cropped in place");
    assert_eq!(bits(&got), bits(&want));
    assert_eq!(
        (got.horizon, got.offset_x, got.offset_y, got.crop_radius_px),
        (
            want.horizon,
            want.offset_x,
            want.offset_y,
            want.crop_radius_px
        )
    );
    // The whole frame (not the square): copied, the same result.
    let whole = crop_dome_owned(img.clone(), (0, 0), &lens, 180.0).unwrap();
    assert_eq!(bits(&whole), bits(&want));
    // A window that starts elsewhere than the square: copied, the same result.
    let mut part = skydome::image::HdrImage::new(img.width - 2, img.height - 1);
    for y in 0..part.height {
        let s = 3 * ((y + 1) * img.width + 2);
        part.data[3 * y * part.width..3 * (y + 1) * part.width]
            .copy_from_slice(&img.data[s..s + 3 * part.width]);
    }
    let moved = crop_dome_owned(part, (2, 1), &lens, 180.0).unwrap();
    assert_eq!(bits(&moved), bits(&want));
}

fn samples(lens: Lens, noise_px: f64) -> Vec<AngleRadius> {
    let mut rng = Noise::new(7);
    (1..=23)
        .map(|i| {
            let a = 5.0 * i as f64;
            AngleRadius {
                angle_deg: a,
                radius_px: lens.r(a.to_radians()) + noise_px * rng.next(),
            }
        })
        .collect()
}

#[test]
fn fit_recovers_the_generating_model_and_focal_length() {
    for kind in [
        LensKind::Equidistant,
        LensKind::Equisolid,
        LensKind::Stereographic,
    ] {
        let truth = Lens::for_circle(kind.name(), 235.0, 1000.0);
        let fit = fit_projection(&samples(truth, 0.3), None).unwrap();
        assert_eq!(
            fit.best.projection.kind(),
            kind,
            "auto choice; candidates {:?}",
            fit.candidates
        );
        let f = match fit.best.projection {
            Projection::Equidistant { f_px }
            | Projection::Equisolid { f_px }
            | Projection::Stereographic { f_px } => f_px,
            other => panic!("{other:?}"),
        };
        let f_true = match truth {
            Lens::Equidistant(f) | Lens::Equisolid(f) | Lens::Stereographic(f) => f,
            _ => unreachable!(),
        };
        assert!((f / f_true - 1.0).abs() < 5e-4, "{kind}: f {f} vs {f_true}");
        assert!(fit.best.rms_px < 0.3);
        // Every other one-parameter model that could be fitted is clearly worse.
        for c in &fit.candidates {
            if c.projection.kind() != kind && c.projection.kind() != LensKind::Polynomial {
                assert!(c.rms_px > 5.0 * fit.best.rms_px, "{kind} vs {:?}", c);
            }
        }
    }
    // Orthographic data only up to 85°.
    let truth = Lens::Orthographic(700.0);
    let s: Vec<_> = samples(truth, 0.2)
        .into_iter()
        .filter(|s| s.angle_deg <= 85.0)
        .collect();
    let fit = fit_projection(&s, None).unwrap();
    assert_eq!(fit.best.projection.kind(), LensKind::Orthographic);
}

#[test]
fn fit_recovers_polynomial_coefficients() {
    let truth = Lens::Polynomial(480.0, -20.0, 1.2);
    let fit = fit_projection(&samples(truth, 0.0), None).unwrap();
    let Projection::Polynomial { k1, k3, k5 } = fit.best.projection else {
        panic!("auto should pick the polynomial: {:?}", fit.candidates);
    };
    assert!(
        (k1 - 480.0).abs() < 1e-6 && (k3 + 20.0).abs() < 1e-6 && (k5 - 1.2).abs() < 1e-6,
        "{k1} {k3} {k5}"
    );
    let noisy = fit_projection(&samples(truth, 0.5), Some(LensKind::Polynomial)).unwrap();
    let Projection::Polynomial { k1, k3, k5 } = noisy.best.projection else {
        unreachable!()
    };
    assert!(
        (k1 - 480.0).abs() < 2.0 && (k3 + 20.0).abs() < 3.0 && (k5 - 1.2).abs() < 0.6,
        "{k1} {k3} {k5}"
    );
    assert!(noisy.best.rms_px < 0.5);
}

#[test]
fn fit_rejects_absurd_measurements() {
    let bad = [AngleRadius {
        angle_deg: 200.0,
        radius_px: 10.0,
    }];
    assert!(matches!(
        fit_projection(&bad, None),
        Err(FisheyeError::BadSample { .. })
    ));
    let bad = [AngleRadius {
        angle_deg: 20.0,
        radius_px: -1.0,
    }];
    assert!(matches!(
        fit_projection(&bad, None),
        Err(FisheyeError::BadSample { .. })
    ));
    let bad = [AngleRadius {
        angle_deg: f64::NAN,
        radius_px: 1.0,
    }];
    assert!(fit_projection(&bad, None).is_err());
    let two = [
        AngleRadius {
            angle_deg: 10.0,
            radius_px: 50.0,
        },
        AngleRadius {
            angle_deg: 20.0,
            radius_px: 100.0,
        },
    ];
    assert!(matches!(
        fit_projection(&two, Some(LensKind::Polynomial)),
        Err(FisheyeError::TooFewSamples { .. })
    ));
    assert!(fit_projection(&[], None).is_err());
    // Two points are enough for a one-parameter model.
    assert_eq!(
        fit_projection(&two, None).unwrap().best.projection.kind(),
        LensKind::Equidistant
    );
}

#[test]
fn lens_profile_json_round_trips_and_validates() {
    let circle = Circle {
        cx: 150.2,
        cy: 141.1,
        r: 130.4,
    };
    for kind in [
        LensKind::Stereographic,
        LensKind::Equidistant,
        LensKind::Equisolid,
    ] {
        let p = LensProfile::from_fov(circle, 235.0, kind).unwrap();
        let json = p.to_json().unwrap();
        assert!(json.contains("\"version\": 1"), "{json}");
        assert!(json.contains(kind.name()));
        let back = LensProfile::from_json(&json).unwrap();
        assert_eq!(back, p);
        assert!((back.projection.radius(117.5f64.to_radians()) - circle.r).abs() < 1e-9);
    }
    let p = LensProfile::from_fov(circle, 235.0, LensKind::Stereographic).unwrap();
    let json = p.to_json().unwrap();
    assert!(matches!(
        LensProfile::from_json(&json.replace("\"version\": 1", "\"version\": 9")),
        Err(FisheyeError::Version(9))
    ));
    assert!(LensProfile::from_json(&json.replace("235.0", "-5.0")).is_err());
    assert!(LensProfile::from_json("{ not json").is_err());
    // A polynomial that folds back inside the field is refused.
    let mut bad = p.clone();
    bad.projection = Projection::Polynomial {
        k1: 100.0,
        k3: -40.0,
        k5: 0.0,
    };
    assert!(matches!(
        bad.validate(),
        Err(FisheyeError::NotMonotonic { .. })
    ));
    assert!(Projection::from_fov(LensKind::Polynomial, 235.0, 100.0).is_err());
    assert!(Projection::from_fov(LensKind::Equidistant, 400.0, 100.0).is_err());
    assert!(Projection::from_fov(LensKind::Equidistant, 180.0, f64::INFINITY).is_err());
}

fn detect_on(dome: &Dome, sky: Sky<'_>, exposure: f32, noise: f64) -> CircleFit {
    let img = dome.render(sky);
    let frame = to_u8(&img, exposure, noise, 99);
    detect_circle(&frame).unwrap()
}

#[test]
fn circle_centre_and_radius_within_one_pixel_on_a_full_circle() {
    let dome = Dome {
        width: 640,
        height: 480,
        cx: 322.4,
        cy: 236.7,
        lens: Lens::for_circle("stereographic", 235.0, 205.3),
        visible_r: 205.3,
        north_deg: 20.0,
        housing: 0.002,
        ss: 3,
    };
    let sky = sunny_sky(120.0, 35.0, 1.0, 50.0);
    let fit = detect_on(&dome, &sky, 1.0, 2.0);
    let truth = Circle {
        cx: dome.cx,
        cy: dome.cy,
        r: dome.visible_r,
    };
    eprintln!("full circle: {fit:?}");
    assert!(
        circle_close(&fit.circle, &truth, 1.0),
        "{fit:?} vs {truth:?}"
    );
    assert!(fit.residual_px < 1.0);
    assert!(fit.points > 500);
}

#[test]
fn circle_found_when_cut_by_the_frame_edge() {
    // The circle pokes out at the top and bottom of a landscape frame.
    let dome = Dome {
        width: 640,
        height: 400,
        cx: 318.2,
        cy: 204.9,
        lens: Lens::for_circle("equidistant", 235.0, 245.6),
        visible_r: 245.6,
        north_deg: 0.0,
        housing: 0.002,
        ss: 3,
    };
    let sky = sunny_sky(200.0, 50.0, 1.0, 50.0);
    let fit = detect_on(&dome, &sky, 1.0, 2.0);
    let truth = Circle {
        cx: dome.cx,
        cy: dome.cy,
        r: dome.visible_r,
    };
    eprintln!("cut circle: {fit:?}");
    assert!(
        circle_close(&fit.circle, &truth, 1.0),
        "{fit:?} vs {truth:?}"
    );
}

#[test]
fn circle_found_when_the_horizon_is_dark() {
    let dome = Dome {
        width: 600,
        height: 500,
        cx: 297.6,
        cy: 252.1,
        lens: Lens::for_circle("equisolid", 235.0, 221.0),
        visible_r: 221.0,
        north_deg: 0.0,
        housing: 0.0,
        ss: 3,
    };
    // Bright zenith, the last 40° (everything below 12° elevation down to −27.5°) dark: code ≈ 25
    // against a housing of ≈ 0–3.
    let sky = |_az: f64, el: f64| {
        if el < 12.0 {
            [0.008; 3]
        } else {
            [0.5, 0.6, 0.9]
        }
    };
    let fit = detect_on(&dome, &sky, 1.0, 1.5);
    let truth = Circle {
        cx: dome.cx,
        cy: dome.cy,
        r: dome.visible_r,
    };
    eprintln!("dark horizon: {fit:?}");
    assert!(
        circle_close(&fit.circle, &truth, 1.0),
        "{fit:?} vs {truth:?}"
    );
}

#[test]
fn detection_rejects_blank_and_tiny_images() {
    let blank = skydome::image::RgbImage::<u8>::new(100, 100);
    assert!(matches!(
        detect_circle(&blank),
        Err(FisheyeError::NoCircle { .. })
    ));
    let tiny = skydome::image::RgbImage::<u8>::new(8, 8);
    assert!(matches!(
        detect_circle(&tiny),
        Err(FisheyeError::ImageTooSmall { .. })
    ));
    assert!(matches!(
        detect_circle_luma(&[0u8; 10], 100, 100),
        Err(FisheyeError::BufferSize(_))
    ));
}

/// A picture like Chromium's fake camera: a bright pie slice of a disc (radius 240 px, a
/// quarter of it filled) on an even mid-green background, 640 × 480; `housing` paints the
/// outside of the disc instead, `full` fills the whole disc.
fn test_pattern(housing: Option<[u8; 3]>, full: bool) -> skydome::image::RgbImage<u8> {
    let (w, h) = (640usize, 480usize);
    let (cx, cy, r) = (320.0f64, 240.0f64, 200.0f64);
    let mut img = skydome::image::RgbImage::<u8>::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
            let inside = dx.hypot(dy) <= r;
            let slice = full || (dx > 0.0 && dy > 0.0);
            let px = match (inside, slice, housing) {
                (true, true, _) => [70, 255, 20],
                (false, _, Some(c)) => c,
                _ => [0, 128, 0],
            };
            img.data[3 * (y * w + x)..][..3].copy_from_slice(&px);
        }
    }
    img
}

#[test]
fn a_circle_without_a_dark_housing_is_doubted() {
    // The fake camera's pie slice on green: its arc fits a circle, but the corners are half as
    // bright as what the fit takes for the circle's inside (50 %), so it is no lens's circle.
    for full in [false, true] {
        let err = detect_circle(&test_pattern(None, full)).unwrap_err();
        eprintln!("test pattern (full disc {full}): {err}");
        match err {
            FisheyeError::NoHousing { housing_percent } => assert!(
                housing_percent > 35.0,
                "{housing_percent} % is above the 35 % limit"
            ),
            e => panic!("expected NoHousing, got {e}"),
        }
    }
    // The same picture with a black housing around the disc is a lens circle, found within a
    // pixel (the control: the doubt is about the housing, not the pattern).
    let fit = detect_circle(&test_pattern(Some([0, 0, 0]), false)).unwrap();
    let truth = Circle {
        cx: 320.0,
        cy: 240.0,
        r: 200.0,
    };
    assert!(circle_close(&fit.circle, &truth, 1.0), "{fit:?}");
    // A housing at 30 % of the green (a flare-lit housing) is still one.
    let grey = Some([0, 38, 0]);
    assert!(detect_circle(&test_pattern(grey, false)).is_ok());
}

#[test]
fn circle_found_on_the_real_alpnach_all_sky_frames() {
    let Some(dir) = shared_data("skycam_alpnach_fisheye") else {
        return;
    };
    let f12 = detect_circle(&load_rgb8(&alpnach_frame(&dir, 12))).unwrap();
    eprintln!("Alpnach frame 12: {f12:?}");
    // README: centre ≈ (150, 141), r ≈ 130.
    assert!((f12.circle.cx - 150.0).abs() < 3.0, "{f12:?}");
    assert!((f12.circle.cy - 141.0).abs() < 3.0, "{f12:?}");
    assert!((f12.circle.r - 130.0).abs() < 4.0, "{f12:?}");
    assert!(f12.residual_px < 1.5, "{f12:?}");
    assert!(f12.points > 300, "{f12:?}");
    // A mid exposure finds the same circle.
    let f10 = detect_circle(&load_rgb8(&alpnach_frame(&dir, 10))).unwrap();
    eprintln!("Alpnach frame 10: {f10:?}");
    assert!(
        circle_close(&f10.circle, &f12.circle, 2.0),
        "{f10:?} vs {f12:?}"
    );
}

#[test]
fn kinds_parse_from_their_names() {
    for k in KINDS {
        assert_eq!(k.name().parse::<LensKind>().unwrap(), k);
    }
    assert!("fisheye".parse::<LensKind>().is_err());
}
