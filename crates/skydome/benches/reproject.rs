//! Reprojection speed. The floor is the same map with one bilinear tap per output pixel
//! (`max_supersample = 1`): the ratio filtered / floor is the price of anti-aliasing.
//! Source: a 1200×1200 stereographic 235° dome (the Alpnach originals' size).

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use skydome::fisheye::{LensKind, LensProfile};
use skydome::image::{Circle, HdrImage};
use skydome::reproject::*;
use skydome::sky::{DevicePose, ImageOrientation, SkyGeometry};

fn source() -> (HdrImage, SkyGeometry) {
    let n = 1200;
    let circle = Circle {
        cx: 600.0,
        cy: 600.0,
        r: 580.0,
    };
    let lens = LensProfile::from_fov(circle, 235.0, LensKind::Stereographic).expect("lens");
    let g = SkyGeometry::new(
        &lens,
        30.0,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    )
    .expect("geometry");
    let mut img = HdrImage::new(n, n);
    for y in 0..n {
        for x in 0..n {
            let v = ((x * 7 + y * 13) % 97) as f32 / 97.0;
            img.set_pixel(x, y, [v, 0.5 * v, 1.0 - v]);
        }
    }
    (img, g)
}

fn bench(c: &mut Criterion) {
    let (img, g) = source();
    let mut group = c.benchmark_group("reproject_1200px_dome");
    group.sample_size(10);
    for (name, map) in [
        (
            "equirect_2048",
            MapProjection::Equirect {
                width: 2048,
                centre_azimuth_deg: 90.0,
            },
        ),
        (
            "equirect_512",
            MapProjection::Equirect {
                width: 512,
                centre_azimuth_deg: 90.0,
            },
        ),
        (
            "angular_1024",
            MapProjection::Angular {
                size: 1024,
                centre_azimuth_deg: 0.0,
            },
        ),
    ] {
        group.bench_function(format!("{name}_filtered"), |b| {
            b.iter(|| reproject(black_box(&img), &g, &map, &ReprojectOptions::default()))
        });
        group.bench_function(format!("{name}_single_tap_floor"), |b| {
            let o = ReprojectOptions {
                max_supersample: 1,
                ..Default::default()
            };
            b.iter(|| reproject(black_box(&img), &g, &map, &o))
        });
    }
    group.bench_function("horizontal_irradiance_fisheye", |b| {
        b.iter(|| horizontal_irradiance_fisheye(black_box(&img), &g))
    });
    group.finish();
}

criterion_group! {
    name = benches;
    // criterion's HTML plots need a system font this workspace does not register; the numbers
    // are printed either way.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
