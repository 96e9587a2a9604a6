//! Lit-sphere rendering: lat-long convention, SH irradiance accuracy, and the sun's reflection
//! in the mirror sphere where geometry says it must be.

use std::f64::consts::PI;

use skydome::image::{luminance, HdrImage};
use skydome::render::{
    direction_from_azimuth_elevation, direction_to_equirect_uv, equirect_uv_to_direction,
    render_spheres, render_spheres_hdr, RenderError, ShIrradiance, SphereScene,
};
use skydome::tonemap::ToneMap;

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}

/// A dim sky (zenith-to-horizon gradient) with a small bright sun at `(az, el)` degrees. Returns
/// the map and the sun's radiance.
fn sky_with_sun(w: usize, az: f64, el: f64, radius_deg: f64, sun_l: f32) -> HdrImage {
    let h = w / 2;
    let mut img = HdrImage::new(w, h);
    let s = direction_from_azimuth_elevation(az, el);
    let cos_r = radius_deg.to_radians().cos();
    for y in 0..h {
        for x in 0..w {
            let d =
                equirect_uv_to_direction((x as f64 + 0.5) / w as f64, (y as f64 + 0.5) / h as f64);
            if d[2] < 0.0 {
                continue;
            }
            let t = 1.0 - d[2] as f32;
            let mut p = [0.2 + 0.2 * t, 0.3 + 0.2 * t, 0.6 + 0.1 * t];
            if dot(d, s) >= cos_r {
                p = [sun_l; 3];
            }
            img.set_pixel(x, y, p);
        }
    }
    img
}

#[test]
fn render_reads_the_equirect_map_reproject_writes() {
    use skydome::reproject::MapProjection;
    let map = MapProjection::Equirect {
        width: 360,
        centre_azimuth_deg: 90.0,
    };
    for (x, y) in [(10.5, 30.5), (90.5, 90.0), (200.25, 10.75), (300.0, 170.0)] {
        let v = map.pixel_to_vector(x, y).unwrap().unwrap();
        let d = equirect_uv_to_direction(x / 360.0, y / 180.0);
        let dist = ((v[0] - d[0]).powi(2) + (v[1] - d[1]).powi(2) + (v[2] - d[2]).powi(2)).sqrt();
        assert!(dist < 1e-9, "({x}, {y}): reproject {v:?} vs render {d:?}");
    }
}

#[test]
fn equirect_convention_north_at_quarter_east_at_centre_south_at_three_quarters_zenith_on_top() {
    let cases = [
        ([0.0, 1.0, 0.0], (0.25, 0.5)),
        ([1.0, 0.0, 0.0], (0.5, 0.5)),
        ([0.0, -1.0, 0.0], (0.75, 0.5)),
        ([-1.0, 0.0, 0.0], (0.0, 0.5)),
        ([0.0, 0.0, 1.0], (0.25, 0.0)),
        ([0.0, 0.0, -1.0], (0.25, 1.0)),
    ];
    for (d, (u, v)) in cases {
        let (gu, gv) = direction_to_equirect_uv(d);
        assert!(
            (gu - u).abs() < 1e-12 && (gv - v).abs() < 1e-12,
            "{d:?} → ({gu}, {gv})"
        );
    }
    let e = direction_from_azimuth_elevation(90.0, 0.0);
    assert!((e[0] - 1.0).abs() < 1e-12, "azimuth 90° is east: {e:?}");
    for i in 0..200 {
        let u = (i as f64 * 0.137) % 1.0;
        let v = 0.01 + 0.98 * ((i as f64 * 0.291) % 1.0);
        let (gu, gv) = direction_to_equirect_uv(equirect_uv_to_direction(u, v));
        assert!(
            (gu - u).abs() < 1e-9 && (gv - v).abs() < 1e-9,
            "({u},{v}) → ({gu},{gv})"
        );
    }
}

#[test]
fn sh_irradiance_of_uniform_light_is_pi_times_radiance() {
    let l = [2.0f32, 0.5, 1.25];
    let env = HdrImage::from_vec(128, 64, [l; 128 * 64].concat()).unwrap();
    let sh = ShIrradiance::from_equirect(&env).unwrap();
    for n in [
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [1.0, 0.0, 0.0],
        [0.3, -0.4, 0.5],
    ] {
        let e = sh.irradiance(n);
        for k in 0..3 {
            let want = PI * l[k] as f64;
            assert!(
                (e[k] / want - 1.0).abs() < 0.01,
                "n={n:?}: {} vs {want}",
                e[k]
            );
        }
    }
}

/// Order-2 truncation of the clamped cosine for a unit-power directional light at angle γ:
/// Σ_l Â_l (2l+1)/(4π) P_l(cos γ).
fn truncated_cosine(cos_g: f64) -> f64 {
    let p2 = 0.5 * (3.0 * cos_g * cos_g - 1.0);
    (PI + 2.0 * PI / 3.0 * 3.0 * cos_g + PI / 4.0 * 5.0 * p2) / (4.0 * PI)
}

#[test]
fn sh_irradiance_of_a_directional_light_matches_the_clamped_cosine_within_order_2_error() {
    // A 3°-radius disc on a black background at azimuth 120°, elevation 35°.
    let (w, h) = (512usize, 256usize);
    let s = direction_from_azimuth_elevation(120.0, 35.0);
    let mut env = HdrImage::new(w, h);
    let mut power = 0.0; // Σ L dω, the light's irradiance at normal incidence
    let cos_r = 3f64.to_radians().cos();
    for y in 0..h {
        let v = (y as f64 + 0.5) / h as f64;
        let dw = (PI * (0.5 - v)).cos() * (2.0 * PI / w as f64) * (PI / h as f64);
        for x in 0..w {
            let d = equirect_uv_to_direction((x as f64 + 0.5) / w as f64, v);
            if dot(d, s) >= cos_r {
                env.set_pixel(x, y, [1000.0; 3]);
                power += 1000.0 * dw;
            }
        }
    }
    let sh = ShIrradiance::from_equirect(&env).unwrap();
    // The worst order-2 error of a directional light, relative to its power: max over γ of
    // |truncated − clamped cosine| (≈ 0.094 at γ = 90°).
    let bound = (0..=1800)
        .map(|i| {
            let g = PI * i as f64 / 1800.0;
            (truncated_cosine(g.cos()) - g.cos().max(0.0)).abs()
        })
        .fold(0.0, f64::max);
    assert!(bound < 0.1);
    let mut worst_trunc = 0.0f64;
    let mut worst_exact = 0.0f64;
    for i in 0..400 {
        let n = norm([
            ((i * 37) % 101) as f64 / 50.0 - 1.0,
            ((i * 53) % 97) as f64 / 48.0 - 1.0,
            ((i * 71) % 89) as f64 / 44.0 - 1.0,
        ]);
        let e = sh.irradiance(n)[0];
        let exact = power * dot(n, s).max(0.0);
        let trunc = power * truncated_cosine(dot(n, s)).max(0.0);
        worst_trunc = worst_trunc.max((e - trunc).abs() / power);
        worst_exact = worst_exact.max((e - exact).abs() / power);
    }
    println!(
        "directional light: SH vs analytic order-2 {:.4} %, vs clamped cosine {:.4} (bound {bound:.4}) of peak",
        100.0 * worst_trunc,
        worst_exact
    );
    assert!(worst_trunc < 0.01, "SH projection error {worst_trunc}");
    assert!(worst_exact <= bound + 0.01, "{worst_exact} > {bound}");
}

/// Where on the picture the mirror sphere shows direction `s`: solve for the sphere point whose
/// normal bisects the view ray and `s`, by fixed-point iteration, and project it.
fn reflected_pixel(scene: &SphereScene, s: [f64; 3]) -> (f64, f64) {
    let cam = scene.camera();
    let m = scene.mirror_sphere();
    let mut n = norm([
        s[0] - cam.forward[0],
        s[1] - cam.forward[1],
        s[2] - cam.forward[2],
    ]);
    for _ in 0..200 {
        let p = [
            m.centre[0] + m.radius * n[0],
            m.centre[1] + m.radius * n[1],
            m.centre[2] + m.radius * n[2],
        ];
        let v = norm([
            p[0] - cam.position[0],
            p[1] - cam.position[1],
            p[2] - cam.position[2],
        ]);
        n = norm([s[0] - v[0], s[1] - v[1], s[2] - v[2]]);
    }
    let p = [
        m.centre[0] + m.radius * n[0],
        m.centre[1] + m.radius * n[1],
        m.centre[2] + m.radius * n[2],
    ];
    cam.project(p).unwrap()
}

#[test]
fn mirror_sphere_shows_the_sun_at_its_reflected_direction() {
    for (view, sun_az, sun_el) in [
        (0.0, 180.0, 30.0),
        (20.0, 150.0, 50.0),
        (250.0, 100.0, 20.0),
    ] {
        let scene = SphereScene {
            view_azimuth_deg: view,
            width: 480,
            height: 240,
            samples_per_axis: 1,
            ..SphereScene::default()
        };
        let env = sky_with_sun(1024, sun_az, sun_el, 1.0, 50_000.0);
        let img = render_spheres_hdr(&env, &scene).unwrap();
        // The mirror sphere's pixels: rays that hit it.
        let cam = scene.camera();
        let m = scene.mirror_sphere();
        let mut best = (0.0f32, 0usize, 0usize);
        for y in 0..img.height {
            for x in 0..img.width {
                let d = cam.ray(x as f64 + 0.5, y as f64 + 0.5);
                let oc = [
                    cam.position[0] - m.centre[0],
                    cam.position[1] - m.centre[1],
                    cam.position[2] - m.centre[2],
                ];
                let b = dot(oc, d);
                if b * b - (dot(oc, oc) - 1.0) < 0.0 {
                    continue;
                }
                let l = luminance(img.pixel(x, y));
                if l > best.0 {
                    best = (l, x, y);
                }
            }
        }
        let s = direction_from_azimuth_elevation(sun_az, sun_el);
        let (ex, ey) = reflected_pixel(&scene, s);
        let (bx, by) = (best.1 as f64 + 0.5, best.2 as f64 + 0.5);
        let err = ((bx - ex).powi(2) + (by - ey).powi(2)).sqrt();
        println!("view {view}°, sun {sun_az}°/{sun_el}°: brightest ({bx}, {by}), expected ({ex:.2}, {ey:.2}), off by {err:.2} px");
        assert!(err <= 2.0, "sun reflection off by {err} px");
        assert!(best.0 > 1000.0, "the reflection is the sun: {}", best.0);
    }
}

#[test]
fn diffuse_sphere_is_brighter_on_the_sunny_side_and_the_ground_shows_its_shadow() {
    // Sun in the north-east, camera facing north: shadows fall towards the south-west, i.e.
    // towards the camera and to the left.
    let scene = SphereScene {
        width: 480,
        height: 360,
        samples_per_axis: 1,
        ..SphereScene::default()
    };
    let (az, el) = (30.0, 40.0);
    let env = sky_with_sun(512, az, el, 1.5, 20_000.0);
    let img = render_spheres_hdr(&env, &scene).unwrap();
    let cam = scene.camera();
    let d = scene.diffuse_sphere();
    let s = direction_from_azimuth_elevation(az, el);
    let px = |img: &HdrImage, p: [f64; 3]| {
        let (x, y) = cam.project(p).unwrap();
        luminance(img.pixel(x as usize, y as usize))
    };
    // Sun behind the camera, 40° up: the sphere's upper front faces it, its underside faces
    // only the ground.
    let front = render_spheres_hdr(&sky_with_sun(512, 200.0, 40.0, 1.5, 20_000.0), &scene).unwrap();
    let lit = [d.centre[0], d.centre[1], d.centre[2] + 0.7];
    let dark = [d.centre[0], d.centre[1], d.centre[2] - 0.9];
    println!(
        "diffuse sphere: sunny side {:.3}, underside {:.3}",
        px(&front, lit),
        px(&front, dark)
    );
    assert!(px(&front, lit) > 3.0 * px(&front, dark));
    // Shadow of the mirror sphere's centre on the ground, versus the nearest visible ground
    // point that both spheres leave in the sun.
    let m = scene.mirror_sphere();
    let t = m.centre[2] / s[2];
    let shadow = [m.centre[0] - t * s[0], m.centre[1] - t * s[1], 0.0];
    let hits = |o: [f64; 3], dir: [f64; 3]| {
        [d, m].iter().any(|sp| {
            let oc = [
                o[0] - sp.centre[0],
                o[1] - sp.centre[1],
                o[2] - sp.centre[2],
            ];
            let b = dot(oc, dir);
            let disc = b * b - (dot(oc, oc) - sp.radius * sp.radius);
            disc >= 0.0 && -b + disc.sqrt() > 0.0
        })
    };
    let visible = |p: [f64; 3]| {
        let Some((x, y)) = cam.project(p) else {
            return false;
        };
        let dir = norm([
            p[0] - cam.position[0],
            p[1] - cam.position[1],
            p[2] - cam.position[2],
        ]);
        (0.0..480.0).contains(&x) && (0.0..360.0).contains(&y) && !hits(cam.position, dir)
    };
    assert!(visible(shadow), "shadow centre hidden or off-picture");
    let mut beside = None;
    for i in 0..400 {
        let r = 0.8 + 0.05 * (i / 16) as f64;
        let a = 2.0 * PI * (i % 16) as f64 / 16.0;
        let p = [shadow[0] + r * a.cos(), shadow[1] + r * a.sin(), 0.0];
        if visible(p) && !hits(p, s) {
            beside = Some(p);
            break;
        }
    }
    let beside = beside.expect("a sunlit ground point near the shadow");
    println!(
        "ground in shadow {:.4} vs in sun {:.4}",
        px(&img, shadow),
        px(&img, beside)
    );
    assert!(px(&img, shadow) < 0.5 * px(&img, beside));
}

#[test]
fn tone_mapped_spheres_are_eight_bit_and_not_black() {
    let env = sky_with_sun(256, 180.0, 30.0, 2.0, 20_000.0);
    let scene = SphereScene {
        width: 160,
        height: 80,
        ..SphereScene::default()
    };
    let out = render_spheres(&env, &scene, &ToneMap::default()).unwrap();
    assert_eq!((out.width, out.height), (160, 80));
    let mean = out.data.iter().map(|v| *v as f64).sum::<f64>() / out.data.len() as f64;
    assert!((40.0..220.0).contains(&mean), "mean {mean}");
}

#[test]
fn bad_scene_or_environment_is_an_error() {
    let env = sky_with_sun(64, 0.0, 45.0, 5.0, 100.0);
    let bad = [
        SphereScene {
            width: 0,
            ..SphereScene::default()
        },
        SphereScene {
            fov_deg: 0.0,
            ..SphereScene::default()
        },
        SphereScene {
            sphere_albedo: 2.0,
            ..SphereScene::default()
        },
        SphereScene {
            samples_per_axis: 100,
            ..SphereScene::default()
        },
    ];
    for s in bad {
        assert!(matches!(
            render_spheres_hdr(&env, &s),
            Err(RenderError::BadParameter { .. })
        ));
    }
    assert!(matches!(
        render_spheres_hdr(&HdrImage::new(2, 1), &SphereScene::default()),
        Err(RenderError::BadEnvironment { .. })
    ));
    assert_eq!(
        render_spheres_hdr(&HdrImage::new(64, 32), &SphereScene::default()),
        Err(RenderError::Dark)
    );
}
