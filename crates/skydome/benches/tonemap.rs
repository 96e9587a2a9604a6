//! Tone-mapping throughput on a 3-megapixel synthetic dome, against a floor: the cheapest
//! possible 8-bit conversion (`min(v, 1) · 255` per sample, one pass, no curve, no statistics)
//! over the same buffer. Report `tonemap_u8 / floor` as the ratio.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use skydome::image::HdrImage;
use skydome::tonemap::{luminance_stats, tonemap_u8, Operator, ToneMap};
use std::hint::black_box;

fn dome(w: usize, h: usize) -> HdrImage {
    let mut img = HdrImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let t = (x as f32 / w as f32 - 0.5).powi(2) + (y as f32 / h as f32 - 0.5).powi(2);
            let sun = if (x as i64 - 1200).pow(2) + (y as i64 - 400).pow(2) < 64 {
                50_000.0
            } else {
                1.0
            };
            img.set_pixel(x, y, [0.3 * sun + t, 0.5 * sun + t, 0.9 * sun]);
        }
    }
    img
}

fn bench(c: &mut Criterion) {
    let img = dome(2000, 1500);
    let mut g = c.benchmark_group("tonemap_3mp");
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
    for op in [Operator::MinMax, Operator::Reinhard, Operator::Aces] {
        let tm = ToneMap::with_operator(op);
        g.bench_function(op.name(), |b| {
            b.iter(|| black_box(tonemap_u8(black_box(&img), &tm)))
        });
    }
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
