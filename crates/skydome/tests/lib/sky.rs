//! Pixel ↔ sky-direction mapping, north, poses and EXIF orientation, the sun (detection,
//! ephemeris, cross-check), on synthetic domes and the real Alpnach frames.

use crate::fisheye_support::*;
use skydome::fisheye::{detect_circle, LensKind, LensProfile};
use skydome::formats::PixelPoint;
use skydome::image::Circle;
use skydome::overlay::{draw_overlay, OverlayMarks};
use skydome::sky::*;

fn lens(kind: LensKind) -> LensProfile {
    LensProfile::from_fov(
        Circle {
            cx: 400.3,
            cy: 300.7,
            r: 280.0,
        },
        235.0,
        kind,
    )
    .unwrap()
}

fn geom(kind: LensKind, north: f64, pose: DevicePose, o: ImageOrientation) -> SkyGeometry {
    SkyGeometry::new(&lens(kind), north, pose, o).unwrap()
}

#[test]
fn north_at_top_puts_east_on_the_left_for_an_upward_camera() {
    let g = geom(
        LensKind::Stereographic,
        0.0,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    );
    let r90 = g.horizon_circle().r;
    let n = g.north_point();
    assert!(
        (n.x - 400.3).abs() < 1e-9 && (n.y - (300.7 - r90)).abs() < 1e-9,
        "{n:?}"
    );
    let e = g.compass_point(90.0);
    assert!(
        (e.x - (400.3 - r90)).abs() < 1e-9 && (e.y - 300.7).abs() < 1e-9,
        "east {e:?}"
    );
    let w = g.compass_point(270.0);
    assert!(w.x > 400.3 + r90 - 1e-9, "west on the right {w:?}");
    let s = g.compass_point(180.0);
    assert!(s.y > 300.7 + r90 - 1e-9, "south at the bottom {s:?}");
}

#[test]
fn mapping_matches_the_closed_form_for_any_compass_azimuth() {
    for kind in [
        LensKind::Stereographic,
        LensKind::Equidistant,
        LensKind::Equisolid,
    ] {
        for north in [0.0, 37.5, 90.0, 181.0, 301.2] {
            let g = geom(
                kind,
                north,
                DevicePose::ScreenDown,
                ImageOrientation::Normal,
            );
            let dome = Dome {
                width: 800,
                height: 600,
                cx: 400.3,
                cy: 300.7,
                lens: Lens::for_circle(kind.name(), 235.0, 280.0),
                visible_r: 280.0,
                north_deg: north,
                housing: 0.0,
                ss: 1,
            };
            for az in (0..360).step_by(15) {
                for el in [-25.0, 0.0, 10.0, 45.0, 80.0, 90.0] {
                    let p = g
                        .direction_to_pixel(&Direction::new(az as f64, el))
                        .unwrap();
                    let (x, y) = dome.pixel(az as f64, el);
                    assert!(
                        (p.x - x).abs() < 1e-7 && (p.y - y).abs() < 1e-7,
                        "{kind} A={north} az={az} el={el}: {p:?} vs ({x},{y})"
                    );
                }
            }
            // North point: (cx + r90·sin A, cy − r90·cos A).
            let r90 = g.horizon_circle().r;
            let n = g.north_point();
            let a = north.to_radians();
            assert!(
                (n.x - (400.3 + r90 * a.sin())).abs() < 1e-7
                    && (n.y - (300.7 - r90 * a.cos())).abs() < 1e-7
            );
        }
    }
}

const ORIENTATIONS: [ImageOrientation; 8] = [
    ImageOrientation::Normal,
    ImageOrientation::MirrorHorizontal,
    ImageOrientation::Rotate180,
    ImageOrientation::MirrorVertical,
    ImageOrientation::Transpose,
    ImageOrientation::Rotate90,
    ImageOrientation::Transverse,
    ImageOrientation::Rotate270,
];

#[test]
fn pixel_direction_round_trip_for_every_pose_and_orientation() {
    for pose in [DevicePose::ScreenDown, DevicePose::ScreenUp] {
        for o in ORIENTATIONS {
            assert_eq!(ImageOrientation::from_exif(o.exif()).unwrap(), o);
            let g = geom(LensKind::Equisolid, 63.0, pose, o);
            for az in (0..360).step_by(20) {
                for el in [-27.0, -5.0, 0.0, 30.0, 60.0, 89.0] {
                    let d = Direction::new(az as f64, el);
                    let p = g.direction_to_pixel(&d).unwrap();
                    let back = g.pixel_to_direction(p).unwrap();
                    assert!(
                        d.angle_to(&back) < 1e-8,
                        "{pose:?} {o:?} {d:?} → {p:?} → {back:?}"
                    );
                }
            }
            // Beyond the 235° field there is nothing.
            assert!(g.direction_to_pixel(&Direction::new(0.0, -40.0)).is_none());
        }
    }
    assert!(ImageOrientation::from_exif(9).is_err());
}

#[test]
fn exif_orientation_moves_north_with_the_stored_pixels() {
    let base = geom(
        LensKind::Equidistant,
        0.0,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    );
    let r = base.horizon_circle().r;
    let (cx, cy) = (400.3, 300.7);
    let close = |p: PixelPoint, x: f64, y: f64| (p.x - x).abs() < 1e-9 && (p.y - y).abs() < 1e-9;
    // Tag 6: the viewer rotates the stored image 90° clockwise, so the displayed top came from
    // the stored left edge: north is stored on the left, east (displayed left) stored at the bottom.
    let g = geom(
        LensKind::Equidistant,
        0.0,
        DevicePose::ScreenDown,
        ImageOrientation::Rotate90,
    );
    assert!(close(g.north_point(), cx - r, cy), "{:?}", g.north_point());
    assert!(
        close(g.compass_point(90.0), cx, cy + r),
        "{:?}",
        g.compass_point(90.0)
    );
    // Tag 8: rotated the other way.
    let g = geom(
        LensKind::Equidistant,
        0.0,
        DevicePose::ScreenDown,
        ImageOrientation::Rotate270,
    );
    assert!(close(g.north_point(), cx + r, cy));
    // Tag 3: north at the bottom, east on the right.
    let g = geom(
        LensKind::Equidistant,
        0.0,
        DevicePose::ScreenDown,
        ImageOrientation::Rotate180,
    );
    assert!(close(g.north_point(), cx, cy + r) && close(g.compass_point(90.0), cx + r, cy));
    // Tag 2: a mirrored image shows east on the right like a map.
    let g = geom(
        LensKind::Equidistant,
        0.0,
        DevicePose::ScreenDown,
        ImageOrientation::MirrorHorizontal,
    );
    assert!(close(g.north_point(), cx, cy - r) && close(g.compass_point(90.0), cx + r, cy));
}

#[test]
fn front_and_rear_cameras_looking_up_see_the_same_unmirrored_sky() {
    for north in [0.0, 45.0, 200.0] {
        let rear = geom(
            LensKind::Stereographic,
            north,
            DevicePose::ScreenDown,
            ImageOrientation::Normal,
        );
        let front = geom(
            LensKind::Stereographic,
            north,
            DevicePose::ScreenUp,
            ImageOrientation::Normal,
        );
        for az in (0..360).step_by(30) {
            let d = Direction::new(az as f64, 20.0);
            let (a, b) = (
                rear.direction_to_pixel(&d).unwrap(),
                front.direction_to_pixel(&d).unwrap(),
            );
            assert!((a.x - b.x).abs() < 1e-9 && (a.y - b.y).abs() < 1e-9);
        }
    }
}

#[test]
fn ephemeris_matches_the_nrel_spa_reference_example() {
    // Reda & Andreas (2004), Table A4.1: 2003-10-17 12:30:30 local, UTC−7, ΔT = 67 s.
    let t = time::macros::datetime!(2003-10-17 12:30:30 -7);
    let site = Site {
        latitude_deg: 39.742476,
        longitude_deg: -105.1786,
        height_m: 1830.14,
        refraction: Refraction::Atmosphere {
            pressure_hpa: 820.0,
            temperature_c: 11.0,
        },
    };
    for dt in [Some(67.0), None] {
        let d = sun_ephemeris(t, &site, dt).unwrap();
        let zenith = 90.0 - d.elevation_deg;
        eprintln!(
            "ΔT {dt:?}: azimuth {:.6}° zenith {:.6}°",
            d.azimuth_deg, zenith
        );
        assert!((zenith - 50.11162).abs() < 0.01, "zenith {zenith}");
        assert!(
            (d.azimuth_deg - 194.34024).abs() < 0.01,
            "azimuth {}",
            d.azimuth_deg
        );
    }
    let with_dt = sun_ephemeris(t, &site, Some(67.0)).unwrap();
    assert!((90.0 - with_dt.elevation_deg - 50.11162).abs() < 1e-4);
    assert!((with_dt.azimuth_deg - 194.34024).abs() < 1e-4);
    // Refraction lifts the sun.
    let geometric = sun_ephemeris(
        t,
        &Site {
            refraction: Refraction::None,
            ..site
        },
        Some(67.0),
    )
    .unwrap();
    assert!(with_dt.elevation_deg > geometric.elevation_deg);
    // Absurd inputs are errors, not panics.
    assert!(sun_ephemeris(
        t,
        &Site {
            latitude_deg: 123.0,
            ..site
        },
        None
    )
    .is_err());
    assert!(sun_ephemeris(
        t,
        &Site {
            refraction: Refraction::Atmosphere {
                pressure_hpa: -3.0,
                temperature_c: 0.0
            },
            ..site
        },
        None
    )
    .is_err());
}

fn sunny_dome(kind: &str, north: f64, sun: (f64, f64)) -> Dome {
    let _ = sun;
    Dome {
        width: 700,
        height: 620,
        cx: 351.4,
        cy: 309.2,
        lens: Lens::for_circle(kind, 235.0, 290.0),
        visible_r: 290.0,
        north_deg: north,
        housing: 0.001,
        ss: 4,
    }
}

#[test]
fn detected_sun_round_trips_image_direction_image_within_half_a_degree() {
    for (kind, lk) in [
        ("stereographic", LensKind::Stereographic),
        ("equidistant", LensKind::Equidistant),
        ("equisolid", LensKind::Equisolid),
    ] {
        for (north, sun) in [
            (0.0, (135.0, 40.0)),
            (30.0, (250.0, 12.0)),
            (300.0, (20.0, 75.0)),
        ] {
            let dome = sunny_dome(kind, north, sun);
            let img = dome.render(&sunny_sky(sun.0, sun.1, 0.6, 5000.0));
            let lensp = LensProfile::from_fov(
                Circle {
                    cx: dome.cx,
                    cy: dome.cy,
                    r: 290.0,
                },
                235.0,
                lk,
            )
            .unwrap();
            let g = SkyGeometry::new(
                &lensp,
                north,
                DevicePose::ScreenDown,
                ImageOrientation::Normal,
            )
            .unwrap();
            let det = detect_sun(&img, &g.horizon_circle()).expect("sun visible");
            let dir = g.pixel_to_direction(det.pixel).unwrap();
            let err = angle_between((dir.azimuth_deg, dir.elevation_deg), sun);
            assert!(
                err < 0.5,
                "{kind} A={north} sun {sun:?}: detected {dir:?} ({err}°)"
            );
            assert!(det.confidence > 0.5, "{det:?}");
            let back = g.direction_to_pixel(&dir).unwrap();
            assert!((back.x - det.pixel.x).abs() < 1e-6 && (back.y - det.pixel.y).abs() < 1e-6);
            let (tx, ty) = dome.pixel(sun.0, sun.1);
            eprintln!(
                "{kind} A={north}: sun err {err:.3}°, pixel err {:.3} px, conf {:.2}",
                (det.pixel.x - tx).hypot(det.pixel.y - ty),
                det.confidence
            );
        }
    }
}

#[test]
fn hidden_sun_is_not_detected() {
    let dome = sunny_dome("stereographic", 0.0, (0.0, 0.0));
    // Overcast: CIE-like brightening towards the zenith, no sun.
    let overcast = |_az: f64, el: f64| {
        let l = (1.0 + 2.0 * el.max(0.0).to_radians().sin()) as f32 / 3.0;
        [l, l, l]
    };
    let img = dome.render(&overcast);
    let region = Circle {
        cx: dome.cx,
        cy: dome.cy,
        r: dome.lens.r(std::f64::consts::FRAC_PI_2),
    };
    assert!(detect_sun(&img, &region).is_none());
    // A big sunlit cloud (40° across, 10× the sky) is not a sun either.
    let cloud = |az: f64, el: f64| {
        if angle_between((az, el), (90.0, 45.0)) < 20.0 {
            [10.0f32; 3]
        } else {
            [1.0; 3]
        }
    };
    assert!(detect_sun(&dome.render(&cloud), &region).is_none());
}

#[test]
fn cross_check_reports_the_compass_error_that_makes_azimuths_agree() {
    let sun = (160.0, 33.0);
    let true_north = 40.0;
    let reported = 47.5;
    let dome = sunny_dome("equidistant", true_north, sun);
    let img = dome.render(&sunny_sky(sun.0, sun.1, 0.6, 5000.0));
    let lensp = LensProfile::from_fov(
        Circle {
            cx: dome.cx,
            cy: dome.cy,
            r: 290.0,
        },
        235.0,
        LensKind::Equidistant,
    )
    .unwrap();
    let wrong = SkyGeometry::new(
        &lensp,
        reported,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    )
    .unwrap();
    let det = detect_sun(&img, &wrong.horizon_circle()).unwrap();
    let detected = wrong.pixel_to_direction(det.pixel).unwrap();
    let computed = Direction::new(sun.0, sun.1);
    let cc = cross_check(&detected, &computed);
    eprintln!("{cc:?}");
    assert!(
        (cc.compass_error_deg - (true_north - reported)).abs() < 0.3,
        "{cc:?}"
    );
    assert!(
        (cc.angle_deg - 7.5 * 33f64.to_radians().cos()).abs() < 0.3,
        "{cc:?}"
    );
    let fixed = SkyGeometry::new(
        &lensp,
        reported + cc.compass_error_deg,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    )
    .unwrap();
    let redone = fixed.pixel_to_direction(det.pixel).unwrap();
    assert!(redone.angle_to(&computed) < 0.3, "{redone:?}");
    // Wrap-around: azimuths either side of north.
    let cc = cross_check(&Direction::new(359.0, 10.0), &Direction::new(2.0, 10.0));
    assert!((cc.compass_error_deg - 3.0).abs() < 1e-9);
}

#[test]
fn sun_found_on_the_real_alpnach_frames_and_overlay_written() {
    let Some(dir) = shared_data("skycam_alpnach_fisheye") else {
        return;
    };
    let circle = detect_circle(&load_rgb8(&alpnach_frame(&dir, 12)))
        .unwrap()
        .circle;
    // The short frames 03–04 show only the sun disc, centred at ≈ (83.5, 81.3) (upper left).
    // Up to frame 08 the clipped disc stays centred; from frame 09 glare and a lens ghost towards
    // the upper left pull the blob's centroid several pixels, its saturated core's about two.
    for (i, tol, min_conf) in [(4, 0.5, 0.5), (6, 1.0, 0.5), (8, 1.0, 0.3), (9, 2.5, 0.15)] {
        let frame = load_rgb8(&alpnach_frame(&dir, i));
        let det = detect_sun_u8(&frame, &circle).expect("the sun is visible in the mid frames");
        let off = (det.pixel.x - 83.5).hypot(det.pixel.y - 81.3);
        eprintln!("Alpnach frame {i:02}: {det:?}, {off:.2} px from the disc");
        assert!(off < tol, "frame {i}: {det:?}");
        assert!(det.confidence > min_conf, "frame {i}: {det:?}");
    }
    // Frame 12 is blown out around the sun: no compact blob stands out.
    let f12 = load_rgb8(&alpnach_frame(&dir, 12));
    eprintln!("frame 12: {:?}", detect_sun_u8(&f12, &circle));

    // Overlay on frame 10 with the circle, a 180° horizon for an equidistant 185° guess, north for a
    // camera whose top points north, and the detected sun.
    let lensp = LensProfile::from_fov(circle, 185.0, LensKind::Equidistant).unwrap();
    let g = SkyGeometry::new(
        &lensp,
        0.0,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    )
    .unwrap();
    let sun = detect_sun_u8(&load_rgb8(&alpnach_frame(&dir, 8)), &circle).unwrap();
    let mut preview = load_rgb8(&alpnach_frame(&dir, 10));
    draw_overlay(
        &mut preview,
        &OverlayMarks {
            visible: Some(circle),
            horizon: Some(g.horizon_circle()),
            north: Some(g.north_point()),
            sun: Some(sun.pixel),
        },
    );
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("alpnach_overlay.png");
    image::RgbImage::from_raw(
        preview.width as u32,
        preview.height as u32,
        preview.data.clone(),
    )
    .unwrap()
    .save(&out)
    .unwrap();
    eprintln!("overlay written to {}", out.display());
    // The sun ring is yellow around the sun.
    let ring = preview.pixel((sun.pixel.x + 6.0) as usize, sun.pixel.y as usize);
    assert!(ring[0] > 200 && ring[1] > 180 && ring[2] < 120, "{ring:?}");
    let n = g.north_point();
    let blue = preview.pixel(n.x as usize, n.y as usize);
    assert!(blue[2] > 200 && blue[0] < 80, "{blue:?}");
}

#[test]
fn polynomial_lens_profile_maps_pixels_and_directions_both_ways() {
    use skydome::fisheye::{fit_projection, AngleRadius};
    let truth = Lens::Polynomial(150.0, -6.0, 0.4);
    let samples: Vec<AngleRadius> = (1..=23)
        .map(|i| {
            let a = 5.0 * i as f64;
            AngleRadius {
                angle_deg: a,
                radius_px: truth.r(a.to_radians()),
            }
        })
        .collect();
    let fit = fit_projection(&samples, None).unwrap();
    let lensp = LensProfile::from_fit(400.0, 300.0, 235.0, &fit).unwrap();
    assert!((lensp.circle.r - truth.r(117.5f64.to_radians())).abs() < 1e-6);
    let g = SkyGeometry::new(
        &lensp,
        12.0,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    )
    .unwrap();
    let dome = Dome {
        width: 800,
        height: 600,
        cx: 400.0,
        cy: 300.0,
        lens: truth,
        visible_r: lensp.circle.r,
        north_deg: 12.0,
        housing: 0.0,
        ss: 1,
    };
    for az in (0..360).step_by(40) {
        for el in [-20.0, 0.0, 33.0, 71.0] {
            let p = g
                .direction_to_pixel(&Direction::new(az as f64, el))
                .unwrap();
            let (x, y) = dome.pixel(az as f64, el);
            assert!((p.x - x).abs() < 1e-6 && (p.y - y).abs() < 1e-6);
            let back = g.pixel_to_direction(p).unwrap();
            assert!(back.angle_to(&Direction::new(az as f64, el)) < 1e-7);
        }
    }
}

#[test]
fn radiance_views_read_back_as_the_geometry_that_wrote_them() {
    for (kind, north) in [
        (LensKind::Equidistant, 0.0),
        (LensKind::Stereographic, 37.0),
        (LensKind::Orthographic, -120.0),
    ] {
        let size = 300usize;
        let half = size as f64 / 2.0;
        let c = Circle {
            cx: half,
            cy: half,
            r: half,
        };
        let fov = if kind == LensKind::Orthographic {
            180.0
        } else {
            181.5
        };
        let lens = LensProfile::from_fov(c, fov, kind).unwrap();
        let g = SkyGeometry::new(
            &lens,
            north,
            DevicePose::ScreenDown,
            ImageOrientation::Normal,
        )
        .unwrap();
        let view = g.radiance_view(half).expect("a Radiance view");
        let back = SkyGeometry::from_radiance_view(&view, size, size)
            .unwrap_or_else(|| panic!("{kind:?}: {view}"));
        for (x, y) in [(150.5, 20.0), (40.0, 200.0), (150.0, 150.0), (260.0, 90.0)] {
            let (a, b) = (g.pixel_to_vector(x, y), back.pixel_to_vector(x, y));
            let (a, b) = (a.unwrap(), b.unwrap());
            let d = (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max);
            assert!(d < 1e-5, "{kind:?} at ({x}, {y}): {a:?} vs {b:?} ({view})");
        }
    }
    // Not an upward square fish-eye: nothing to integrate.
    let up = "-vta -vp 0 0 0 -vd 0 0 1 -vu 0 1 0 -vh 180 -vv 180";
    assert!(SkyGeometry::from_radiance_view(up, 100, 100).is_some());
    assert!(SkyGeometry::from_radiance_view(up, 100, 80).is_none());
    let side = "-vta -vp 0 0 0 -vd 0 1 0 -vu 0 0 1 -vh 180 -vv 180";
    assert!(SkyGeometry::from_radiance_view(side, 100, 100).is_none());
    let persp = "-vtv -vp 0 0 0 -vd 0 0 1 -vu 0 1 0 -vh 60 -vv 60";
    assert!(SkyGeometry::from_radiance_view(persp, 100, 100).is_none());
}
