//! The preview of a 6-megapixel dome (2448 × 2448 synthetic fish-eye sky with a sun and a
//! housing as dark as a merge's): statistics, tone mapping (table-driven fast path against the exact per-pixel
//! reference), JPEG encoding (`jpeg-encoder`, which skydome uses, against `image`'s encoder),
//! and the whole preview (tone map + encode), whose target is ≤ 60 ms. A floor — the cheapest
//! possible 8-bit conversion, `min(v, 1) · 255` per sample in one pass — puts the tone map in
//! proportion.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use skydome::formats::picture::{encode_rgb8, PictureFormat, DEFAULT_JPEG_QUALITY};
use skydome::image::{Circle, HdrImage};
use skydome::tonemap::{
    exposure_circle, luminance_stats, tonemap_u8, tonemap_u8_reference, Operator, ToneMap,
};
use std::hint::black_box;

fn dome() -> HdrImage {
    let n = 2448;
    let c = Circle {
        cx: n as f64 / 2.0,
        cy: n as f64 / 2.0,
        r: 0.48 * n as f64,
    };
    let mut img = skydome::synth::scene(n, n, 7, Some(c));
    // A merged photo's housing is not exactly black: the longest frame's code 0 through the
    // response gives a faint level (about 1.6·10⁻⁴ of the sky's median on the bench bracket of
    // `scripts/bench.sh`). Without it the tone map would skip the housing as black, which it
    // cannot do on a real dome.
    let mut lit: Vec<f32> = img
        .data
        .chunks_exact(3)
        .map(|p| p[1])
        .filter(|&g| g > 0.0)
        .collect();
    let mid = lit.len() / 2;
    let median = *lit.select_nth_unstable_by(mid, f32::total_cmp).1;
    for p in img.data.chunks_exact_mut(3) {
        if p == [0.0; 3] {
            p.copy_from_slice(&[0.6, 1.0, 1.4].map(|k| k * 1.6e-4 * median));
        }
    }
    img
}

fn bench(c: &mut Criterion) {
    let img = dome();
    let tm = ToneMap::default();
    let mut g = c.benchmark_group("preview_6mp");
    g.throughput(Throughput::Elements(img.pixel_count() as u64));
    g.sample_size(20);
    g.bench_function("floor_clamp_scale", |b| {
        b.iter(|| {
            let out: Vec<u8> = black_box(&img.data)
                .iter()
                .map(|v| (v.clamp(0.0, 1.0) * 255.0) as u8)
                .collect();
            black_box(out)
        })
    });
    g.bench_function("stats_only", |b| {
        b.iter(|| black_box(luminance_stats(black_box(&img), None)))
    });
    g.bench_function("detect_circle_for_exposure", |b| {
        b.iter(|| black_box(exposure_circle(black_box(&img), &tm)))
    });
    g.bench_function("tonemap_u8_aces", |b| {
        b.iter(|| black_box(tonemap_u8(black_box(&img), &tm)))
    });
    g.bench_function("tonemap_u8_aces_reference", |b| {
        b.iter(|| black_box(tonemap_u8_reference(black_box(&img), &tm)))
    });
    for op in [Operator::Reinhard, Operator::Drago] {
        let t = ToneMap::with_operator(op);
        g.bench_function(format!("tonemap_u8_{}", op.name()), |b| {
            b.iter(|| black_box(tonemap_u8(black_box(&img), &t)))
        });
    }
    let rgb = tonemap_u8(&img, &tm).unwrap();
    let q = DEFAULT_JPEG_QUALITY;
    g.bench_function("encode_jpeg_jpeg_encoder", |b| {
        b.iter(|| {
            black_box(encode_rgb8(
                black_box(&rgb),
                PictureFormat::Jpeg { quality: q },
            ))
        })
    });
    g.bench_function("encode_jpeg_image_crate", |b| {
        use image::ImageEncoder;
        b.iter(|| {
            let mut out = Vec::new();
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, q)
                .write_image(
                    black_box(&rgb.data),
                    rgb.width as u32,
                    rgb.height as u32,
                    image::ExtendedColorType::Rgb8,
                )
                .unwrap();
            black_box(out)
        })
    });
    g.bench_function("preview_tonemap_and_jpeg", |b| {
        b.iter(|| {
            let rgb = tonemap_u8(black_box(&img), &tm).unwrap();
            black_box(encode_rgb8(&rgb, PictureFormat::Jpeg { quality: q }))
        })
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
