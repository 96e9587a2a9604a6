//! Reprojection to equirect / angular / mirror-ball / fish-eye maps: conventions, energy
//! (horizontal irradiance), sun direction, ground fill and anti-aliasing.

use crate::fisheye_support::*;
use skydome::fisheye::{LensKind, LensProfile};
use skydome::image::{Circle, HdrImage};
use skydome::reproject::*;
use skydome::sky::{DevicePose, Direction, ImageOrientation, SkyGeometry};

const R: f64 = 300.0;

fn dome(kind: &str, north: f64) -> Dome {
    Dome {
        width: 640,
        height: 640,
        cx: 320.4,
        cy: 319.6,
        lens: Lens::for_circle(kind, 235.0, R),
        visible_r: R,
        north_deg: north,
        housing: 0.0,
        ss: 3,
    }
}

fn geometry(d: &Dome, kind: LensKind) -> SkyGeometry {
    let lens = LensProfile::from_fov(
        Circle {
            cx: d.cx,
            cy: d.cy,
            r: R,
        },
        235.0,
        kind,
    )
    .unwrap();
    SkyGeometry::new(
        &lens,
        d.north_deg,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    )
    .unwrap()
}

fn maps() -> Vec<MapProjection> {
    vec![
        MapProjection::Equirect {
            width: 1024,
            centre_azimuth_deg: 90.0,
        },
        MapProjection::Angular {
            size: 512,
            centre_azimuth_deg: 0.0,
        },
        MapProjection::MirrorBall {
            size: 512,
            centre_azimuth_deg: 30.0,
        },
        MapProjection::Fisheye {
            size: 400,
            model: LensKind::Equidistant,
            fov_deg: 180.0,
        },
    ]
}

#[test]
fn uniform_sky_gives_pi_l_from_the_dome_and_from_the_equirect_map() {
    for (kind, lk) in [
        ("stereographic", LensKind::Stereographic),
        ("equidistant", LensKind::Equidistant),
        ("equisolid", LensKind::Equisolid),
    ] {
        let d = dome(kind, 25.0);
        let img = d.render(&|_, _| [1.0, 2.0, 0.5]);
        let g = geometry(&d, lk);
        let e = horizontal_irradiance_fisheye(&img, &g);
        let pi = std::f64::consts::PI;
        let rel = (e[0] / pi - 1.0).abs();
        eprintln!(
            "{kind}: fisheye E = {:.5} (π·L error {:.4} %)",
            e[0],
            100.0 * rel
        );
        assert!(rel < 0.01, "{kind}: {e:?}");
        assert!((e[1] / (2.0 * pi) - 1.0).abs() < 0.01 && (e[2] / (0.5 * pi) - 1.0).abs() < 0.01);
        let eq = reproject(
            &img,
            &g,
            &MapProjection::Equirect {
                width: 1024,
                centre_azimuth_deg: 90.0,
            },
            &ReprojectOptions::default(),
        )
        .unwrap();
        let ee = horizontal_irradiance_equirect(&eq);
        let rel = (ee[0] / pi - 1.0).abs();
        eprintln!(
            "{kind}: equirect E = {:.5} (error {:.4} %)",
            ee[0],
            100.0 * rel
        );
        assert!(rel < 0.01, "{kind}: {ee:?}");
    }
}

#[test]
fn sunny_sky_irradiance_is_preserved_through_the_equirect_map() {
    let sun = (150.0, 35.0);
    let d = dome("stereographic", 10.0);
    let img = d.render(&sunny_sky(sun.0, sun.1, 1.5, 2000.0));
    let g = geometry(&d, LensKind::Stereographic);
    let ef = horizontal_irradiance_fisheye(&img, &g);
    // Analytic: sky part + sun disc (solid angle 2π(1 − cos 1.5°) at cos θ = sin 35°).
    let sun_part = 2000.0
        * std::f64::consts::TAU
        * (1.0 - 1.5f64.to_radians().cos())
        * 35f64.to_radians().sin();
    eprintln!(
        "fisheye E = {:.4}, sun share ≈ {:.1} %",
        ef[0],
        100.0 * sun_part / ef[0]
    );
    for width in [512, 2048] {
        let eq = reproject(
            &img,
            &g,
            &MapProjection::Equirect {
                width,
                centre_azimuth_deg: 90.0,
            },
            &ReprojectOptions::default(),
        )
        .unwrap();
        let ee = horizontal_irradiance_equirect(&eq);
        for c in 0..3 {
            let rel = (ee[c] / ef[c] - 1.0).abs();
            eprintln!(
                "equirect {width}: channel {c} E ratio error {:.3} %",
                100.0 * rel
            );
            assert!(rel < 0.01, "width {width} channel {c}: {ee:?} vs {ef:?}");
        }
    }
}

fn brightest_centroid(img: &HdrImage) -> (f64, f64) {
    let peak = img.pixels().map(|p| p[0]).fold(0.0f32, f32::max);
    let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
    for y in 0..img.height {
        for x in 0..img.width {
            let v = img.pixel(x, y)[0];
            if v > 0.25 * peak {
                let w = f64::from(v);
                sx += w * (x as f64 + 0.5);
                sy += w * (y as f64 + 0.5);
                sw += w;
            }
        }
    }
    (sx / sw, sy / sw)
}

#[test]
fn a_point_sun_keeps_its_direction_through_every_reprojection() {
    for (north, sun) in [
        (0.0, (135.0, 40.0)),
        (70.0, (250.0, 15.0)),
        (200.0, (10.0, 70.0)),
    ] {
        let d = dome("equisolid", north);
        let img = d.render(&sunny_sky(sun.0, sun.1, 0.7, 5000.0));
        let g = geometry(&d, LensKind::Equisolid);
        for m in maps() {
            let out = reproject(&img, &g, &m, &ReprojectOptions::default()).unwrap();
            let (x, y) = brightest_centroid(&out);
            let v = m.pixel_to_vector(x, y).unwrap().expect("inside the map");
            let got = Direction::from_vector(v);
            let err = angle_between((got.azimuth_deg, got.elevation_deg), sun);
            eprintln!("{m:?}: sun {sun:?} → {got:?}, {err:.3}°");
            assert!(err < 0.5, "{m:?}: {err}°");
            // And the map's forward mapping puts the true sun where it was found.
            let (px, py) = m
                .vector_to_pixel(Direction::new(sun.0, sun.1).to_vector())
                .unwrap()
                .unwrap();
            let (w, _) = m.dimensions();
            assert!((px - x).hypot(py - y) < 0.01 * w as f64, "{m:?}");
        }
    }
}

#[test]
fn equirect_default_puts_east_at_the_centre_and_north_at_a_quarter_like_blender_plus_y() {
    let m = MapProjection::Equirect {
        width: 1000,
        centre_azimuth_deg: 90.0,
    };
    let at = |az: f64, el: f64| {
        m.vector_to_pixel(Direction::new(az, el).to_vector())
            .unwrap()
            .unwrap()
    };
    let (x, y) = at(0.0, 0.0);
    assert!(
        (x - 250.0).abs() < 1e-9 && (y - 250.0).abs() < 1e-9,
        "north at u = 1/4: {x}"
    );
    assert!(
        (at(90.0, 0.0).0 - 500.0).abs() < 1e-9,
        "east at the centre (Blender +X)"
    );
    assert!(
        (at(180.0, 0.0).0 - 750.0).abs() < 1e-9,
        "south at u = 3/4 (Blender −Y)"
    );
    assert!(at(10.0, 90.0).1.abs() < 1e-9, "zenith on the top row");
    // Blender: u = 1/2 − atan2(y, x)/2π with X = east, Y = north.
    for az in [0.0, 33.0, 90.0, 145.0, 260.0] {
        let v = Direction::new(az, 0.0).to_vector();
        let u_blender = (0.5 - v[1].atan2(v[0]) / std::f64::consts::TAU).rem_euclid(1.0);
        assert!((at(az, 0.0).0 / 1000.0 - u_blender).abs() < 1e-9, "az {az}");
    }
    // And in pixels: a sky bright only towards the north shows its peak at u = 1/4.
    let d = dome("equidistant", 40.0);
    let img = d.render(&|az, el| {
        let l = (angle_between((az, el), (0.0, 5.0)) < 8.0) as u8 as f32;
        [l, l, l]
    });
    let out = reproject(
        &img,
        &geometry(&d, LensKind::Equidistant),
        &m,
        &ReprojectOptions::default(),
    )
    .unwrap();
    let (x, _) = brightest_centroid(&out);
    assert!((x - 250.0).abs() < 3.0, "{x}");
    // North-centred option.
    let m0 = MapProjection::Equirect {
        width: 1000,
        centre_azimuth_deg: 0.0,
    };
    let (x0, _) = m0
        .vector_to_pixel(Direction::new(0.0, 0.0).to_vector())
        .unwrap()
        .unwrap();
    assert!((x0 - 500.0).abs() < 1e-9);
}

#[test]
fn angular_and_mirror_ball_show_the_centre_direction_in_the_middle_and_west_on_the_right() {
    for m in [
        MapProjection::Angular {
            size: 500,
            centre_azimuth_deg: 0.0,
        },
        MapProjection::MirrorBall {
            size: 500,
            centre_azimuth_deg: 0.0,
        },
    ] {
        let at = |az: f64, el: f64| {
            m.vector_to_pixel(Direction::new(az, el).to_vector())
                .unwrap()
                .unwrap()
        };
        let (x, y) = at(0.0, 0.0);
        assert!((x - 250.0).abs() < 1e-9 && (y - 250.0).abs() < 1e-9);
        assert!(at(270.0, 0.0).0 > 250.0, "west on the right");
        assert!(at(0.0, 90.0).1 < 250.0, "zenith up");
        let back = at(180.0, 0.0);
        assert!(
            (back.0 - 250.0).hypot(back.1 - 250.0) > 249.0,
            "the opposite direction is the rim"
        );
    }
    // Fish-eye output: north up, east left.
    let f = MapProjection::Fisheye {
        size: 400,
        model: LensKind::Equidistant,
        fov_deg: 180.0,
    };
    let (nx, ny) = f
        .vector_to_pixel(Direction::new(0.0, 0.0).to_vector())
        .unwrap()
        .unwrap();
    assert!((nx - 200.0).abs() < 1e-9 && ny.abs() < 1e-9);
    let (ex, _) = f
        .vector_to_pixel(Direction::new(90.0, 0.0).to_vector())
        .unwrap()
        .unwrap();
    assert!(ex.abs() < 1e-9);
    let (_, zy) = f
        .vector_to_pixel(Direction::new(0.0, 45.0).to_vector())
        .unwrap()
        .unwrap();
    assert!((zy - 100.0).abs() < 1e-9, "equidistant: 45° halfway");
}

#[test]
fn ground_is_black_constant_or_the_mirrored_sky() {
    let d = dome("stereographic", 0.0);
    let img = d.render(&|az, el| {
        let l = (1.0 + el / 90.0 + az / 360.0) as f32;
        [l, l, l]
    });
    let g = geometry(&d, LensKind::Stereographic);
    let m = MapProjection::Equirect {
        width: 256,
        centre_azimuth_deg: 90.0,
    };
    let black = reproject(
        &img,
        &g,
        &m,
        &ReprojectOptions {
            ground: Ground::Black,
            ..Default::default()
        },
    )
    .unwrap();
    let constant = reproject(
        &img,
        &g,
        &m,
        &ReprojectOptions {
            ground: Ground::Constant([0.2, 0.3, 0.4]),
            ..Default::default()
        },
    )
    .unwrap();
    let mirror = reproject(
        &img,
        &g,
        &m,
        &ReprojectOptions {
            ground: Ground::MirrorSky,
            ..Default::default()
        },
    )
    .unwrap();
    let h = 128;
    for y in (h / 2 + 2)..h {
        for x in 0..256 {
            assert_eq!(black.pixel(x, y), [0.0; 3]);
            assert_eq!(constant.pixel(x, y), [0.2, 0.3, 0.4]);
            let up = mirror.pixel(x, h - 1 - y)[0];
            let down = mirror.pixel(x, y)[0];
            assert!((up - down).abs() < 0.02 * up, "({x},{y}): {up} vs {down}");
        }
    }
    // The sky half is the same whatever the ground.
    for y in 0..(h / 2 - 2) {
        assert_eq!(black.pixel(17, y), mirror.pixel(17, y));
    }
}

#[test]
fn shrinking_averages_the_footprint_instead_of_aliasing() {
    // 180 bright/dark stripes in azimuth: a 64-pixel-wide equirect cannot show them.
    let d = dome("equidistant", 0.0);
    let img = d.render(&|az, _| {
        let l = if (az * 0.5).floor() as i64 % 2 == 0 {
            2.0f32
        } else {
            0.0
        };
        [l, l, l]
    });
    let g = geometry(&d, LensKind::Equidistant);
    let m = MapProjection::Equirect {
        width: 64,
        centre_azimuth_deg: 90.0,
    };
    let stats = |out: &HdrImage| {
        // Row at 30° elevation.
        let y = (60.0 / 180.0 * 32.0) as usize;
        let v: Vec<f64> = (0..64).map(|x| f64::from(out.pixel(x, y)[0])).collect();
        let mean = v.iter().sum::<f64>() / 64.0;
        let sd = (v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / 64.0).sqrt();
        (mean, sd)
    };
    let filtered = stats(&reproject(&img, &g, &m, &ReprojectOptions::default()).unwrap());
    let floor = stats(
        &reproject(
            &img,
            &g,
            &m,
            &ReprojectOptions {
                max_supersample: 1,
                ..Default::default()
            },
        )
        .unwrap(),
    );
    eprintln!(
        "filtered mean {:.3} sd {:.3}; single tap mean {:.3} sd {:.3}",
        filtered.0, filtered.1, floor.0, floor.1
    );
    assert!((filtered.0 - 1.0).abs() < 0.05, "{filtered:?}");
    // A one-pixel box filter leaves some beat of a square wave at 2.8 cycles per output pixel
    // (sd ≈ 0.2 of a 0..2 pattern); single taps keep almost all of it (sd ≈ 0.9).
    assert!(filtered.1 < 0.25, "{filtered:?}");
    assert!(
        floor.1 > 3.0 * filtered.1,
        "the single tap aliases: {floor:?}"
    );
}

#[test]
fn absurd_outputs_are_errors() {
    let d = dome("equidistant", 0.0);
    let img = HdrImage::new(d.width, d.height);
    let g = geometry(&d, LensKind::Equidistant);
    let o = ReprojectOptions::default();
    assert!(matches!(
        reproject(
            &img,
            &g,
            &MapProjection::Equirect {
                width: 0,
                centre_azimuth_deg: 0.0
            },
            &o
        ),
        Err(ReprojectError::BadSize { .. })
    ));
    assert!(reproject(
        &img,
        &g,
        &MapProjection::Equirect {
            width: 101,
            centre_azimuth_deg: 0.0
        },
        &o
    )
    .is_err());
    assert!(reproject(
        &img,
        &g,
        &MapProjection::Angular {
            size: 1 << 20,
            centre_azimuth_deg: 0.0
        },
        &o
    )
    .is_err());
    assert!(reproject(
        &img,
        &g,
        &MapProjection::Angular {
            size: 64,
            centre_azimuth_deg: f64::NAN
        },
        &o
    )
    .is_err());
    assert!(reproject(
        &img,
        &g,
        &MapProjection::Fisheye {
            size: 64,
            model: LensKind::Orthographic,
            fov_deg: 200.0
        },
        &o
    )
    .is_err());
    assert!(reproject(
        &img,
        &g,
        &MapProjection::Fisheye {
            size: 64,
            model: LensKind::Polynomial,
            fov_deg: 180.0
        },
        &o
    )
    .is_err());
    assert!(reproject(
        &img,
        &g,
        &MapProjection::Angular {
            size: 64,
            centre_azimuth_deg: 0.0
        },
        &ReprojectOptions {
            max_supersample: 0,
            ..o
        }
    )
    .is_err());
    let broken = HdrImage {
        width: 10,
        height: 10,
        data: vec![0.0; 5],
    };
    assert!(matches!(
        reproject(
            &broken,
            &g,
            &MapProjection::Angular {
                size: 64,
                centre_azimuth_deg: 0.0
            },
            &o
        ),
        Err(ReprojectError::BufferSize(_))
    ));
}
