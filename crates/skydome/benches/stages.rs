//! The stages of `skydome merge` that have no benchmark of their own elsewhere, on the 6 MP
//! (2448 × 2448) synthetic bracket `scripts/bench.sh` uses: JPEG decoding through
//! `bracket::decode` (one frame, and the three frames in parallel as the CLI does) and the crop
//! to the 180° dome. The other stages: `calibrate` and `merge_6mp` in `calibrate_merge.rs`,
//! `reproject_1200px_dome` in `reproject.rs`, `rgbe_encode_6mp` in `formats.rs`, tone map and
//! preview encoding in `tonemap.rs` (`preview_6mp`).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayon::prelude::*;
use skydome::bracket::{decode, DecodeOptions, Pixels};
use skydome::fisheye::{crop_dome, LensKind, LensProfile};
use skydome::formats::picture::{encode_rgb8, PictureFormat};
use skydome::image::RgbImage;
use skydome::synth::{generate, SynthOptions};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let n = 2448;
    let b = generate(&SynthOptions {
        width: n,
        height: n,
        jpeg_quality: None,
        ..SynthOptions::default()
    })
    .unwrap();
    // The frames as the JPEG files `skydome synth` writes (quality 92, 4:2:0).
    let jpegs: Vec<Vec<u8>> = b
        .frames
        .iter()
        .map(|f| {
            let Pixels::U8(d) = &f.pixels else {
                unreachable!("synthetic frames are 8-bit")
            };
            let img = RgbImage::from_vec(n, n, d.clone()).unwrap();
            encode_rgb8(&img, PictureFormat::Jpeg { quality: 92 }).unwrap()
        })
        .collect();
    let opts = DecodeOptions::default();
    let mut g = c.benchmark_group("stages_6mp");
    g.sample_size(10);
    g.throughput(Throughput::Elements((n * n) as u64));
    g.bench_function("decode_one_jpeg", |bch| {
        bch.iter(|| black_box(decode("f.jpg", black_box(&jpegs[1]), &opts).unwrap()))
    });
    g.throughput(Throughput::Elements((3 * n * n) as u64));
    g.bench_function("decode_three_jpegs_parallel", |bch| {
        bch.iter(|| {
            let v: Vec<_> = jpegs
                .par_iter()
                .map(|j| decode("f.jpg", j, &opts).unwrap())
                .collect();
            black_box(v)
        })
    });
    let circle = b.circle.unwrap();
    let lens = LensProfile::from_fov(circle, 235.0, LensKind::Equidistant).unwrap();
    g.throughput(Throughput::Elements((n * n) as u64));
    g.bench_function("crop_dome_180", |bch| {
        bch.iter(|| black_box(crop_dome(black_box(&b.truth), &lens, 180.0).unwrap()))
    });
    g.finish();
}

// Criterion's own HTML plots go through plotters, which in this workspace uses ab_glyph with no
// registered font and would panic; the numbers are what matter.
criterion_group! {
    name = benches;
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
