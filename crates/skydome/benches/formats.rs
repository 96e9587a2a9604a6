//! `.hdr` and `.exr` speed on a 6 MP sky-like image, against the `image` crate's Radiance
//! encoder/decoder measured in the same run (read the ratio, not the absolute time).

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use image::ImageDecoder;
use skydome::formats::exr::{
    encode_exr, read_exr, ExrCompression, ExrOptions, ExrPixelType, Limits as ExrLimits,
};
use skydome::formats::rgbe::{decode_rgbe, encode_rgbe, float_to_rgbe, Limits};
use skydome::formats::HdrMeta;
use skydome::HdrImage;

/// 3000×2000: a smooth dome with a bright sun, dark mask corners (runs) and sensor-like noise.
fn sky_6mp() -> HdrImage {
    let (w, h) = (3000usize, 2000usize);
    let mut img = HdrImage::new(w, h);
    let mut s = 0x2545f4914f6cdd1du64;
    for y in 0..h {
        for x in 0..w {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let n = 1.0 + ((s >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.02;
            let (dx, dy) = (x as f32 - 1500.0, y as f32 - 1000.0);
            let r = (dx * dx + dy * dy).sqrt() / 1000.0;
            let v = if r > 1.0 {
                [0.0; 3]
            } else {
                let (sx, sy) = (x as f32 - 2000.0, y as f32 - 700.0);
                let sun = 5e4 * (-(sx * sx + sy * sy) / 200.0).exp();
                let sky = 0.5 + 2.0 * (1.0 - r);
                [
                    (sky * 0.7 + sun) * n,
                    (sky * 0.85 + sun) * n,
                    (sky + sun) * n,
                ]
            };
            img.set_pixel(x, y, v);
        }
    }
    img
}

fn bench(c: &mut Criterion) {
    let img = sky_6mp();
    let meta = HdrMeta::default();
    let rgb: Vec<image::Rgb<f32>> = img.pixels().map(image::Rgb).collect();

    let mut g = c.benchmark_group("rgbe_encode_6mp");
    g.sample_size(10);
    g.bench_function("skydome", |b| {
        b.iter(|| black_box(encode_rgbe(black_box(&img), &meta).unwrap()))
    });
    g.bench_function("image_HdrEncoder", |b| {
        b.iter(|| {
            let mut out = Vec::with_capacity(img.data.len() * 4 / 3);
            image::codecs::hdr::HdrEncoder::new(&mut out)
                .encode(black_box(&rgb), img.width, img.height)
                .unwrap();
            black_box(out)
        })
    });

    // Floors: the per-pixel conversion alone (one thread) and a plain copy of the output size.
    g.bench_function("floor_convert_only_1thread", |b| {
        b.iter(|| {
            let v: Vec<[u8; 4]> = black_box(&img).pixels().map(float_to_rgbe).collect();
            black_box(v)
        })
    });
    g.finish();

    let bytes = encode_rgbe(&img, &meta).unwrap();
    let mut g = c.benchmark_group("rgbe_decode_6mp");
    g.sample_size(10);
    g.bench_function("skydome", |b| {
        b.iter(|| black_box(decode_rgbe(black_box(&bytes), &Limits::default()).unwrap()))
    });
    g.bench_function("image_HdrDecoder", |b| {
        b.iter(|| {
            let d = image::codecs::hdr::HdrDecoder::new(black_box(&bytes[..])).unwrap();
            let mut buf = vec![0u8; d.total_bytes() as usize];
            d.read_image(&mut buf).unwrap();
            black_box(buf)
        })
    });
    g.finish();

    let mut g = c.benchmark_group("exr_6mp");
    g.sample_size(10);
    // The library alone compresses on one thread (the CLI turns on exr's `rayon` feature).
    for (name, pixel_type, compression) in [
        ("encode_half", ExrPixelType::Half, ExrCompression::Zip),
        ("encode_float", ExrPixelType::Float, ExrCompression::Zip),
        ("encode_half_piz", ExrPixelType::Half, ExrCompression::Piz),
        ("encode_half_rle", ExrPixelType::Half, ExrCompression::Rle),
    ] {
        let o = ExrOptions {
            pixel_type,
            compression,
        };
        g.bench_function(name, |b| {
            b.iter(|| black_box(encode_exr(black_box(&img), &meta, o).unwrap()))
        });
    }
    let half = encode_exr(&img, &meta, ExrPixelType::Half).unwrap();
    g.bench_function("decode_half", |b| {
        b.iter(|| black_box(read_exr(black_box(&half), &ExrLimits::default()).unwrap()))
    });
    g.finish();
}

criterion_group! {
    name = benches;
    // No plots: the plotters backend needs system fonts that CI machines may lack.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
