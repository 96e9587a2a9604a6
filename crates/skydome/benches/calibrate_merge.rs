//! Calibration and merge speed, each beside a floor or a peer measured in the same run.
//!
//! - `calibrate/schur_100`, `calibrate/schur_600`: the default solver, 3 channels, 3 frames;
//!   `calibrate/dense_svd_100`: the seed's dense SVD of the same system (the ratio to beat).
//! - `merge_6mp/lut`: [`merge`] of 3 frames of 2448 × 2448 into a fresh output;
//!   `merge_6mp/memory_floor`: just reads the same input bytes and writes a fresh output of the
//!   same size (the floor); `merge_6mp/lut_into` and `merge_6mp/memory_floor_into`: the same
//!   with the output buffer reused ([`merge_into`]), which spares the page faults;
//!   `merge_6mp/lut_into_with_confidence_and_mask`: also the confidence and clipped mask;
//!   `merge_6mp/noise_into`: the noise-model merge ([`Weighting::Noise`](skydome::merge::Weighting::Noise):
//!   the noise model's fit from the frames, the hat pass and its refinement);
//!   `merge_6mp/noise_given_into`: the same with the noise model given (no fit);
//!   `merge_6mp/naive`: a straightforward per-pixel `ln`/`exp` weighted merge on one thread
//!   (the peer a simple implementation gives).
//!
//! Run: `cargo bench -p skydome --bench calibrate_merge`.

use criterion::{criterion_group, criterion_main, Criterion};
use skydome::bracket::{Frame, Pixels};
use skydome::merge::{merge, merge_into, MergeOptions};
use skydome::response::{calibrate_samples, solve_dense_svd, Response, Solver};
use skydome::sampling::{sample, SampleOptions};
use skydome::synth::{generate, SynthOptions};
use std::hint::black_box;

fn calibration(c: &mut Criterion) {
    let b = generate(&SynthOptions::default()).unwrap();
    let lt: Vec<f64> = b
        .frames
        .iter()
        .map(|f| f.exposure.relative().ln())
        .collect();
    let s100 = sample(&b.frames, b.circle, &SampleOptions::seed_method(100, 10, 1)).unwrap();
    let s600 = sample(&b.frames, b.circle, &SampleOptions::seed_method(600, 10, 1)).unwrap();
    let mut g = c.benchmark_group("calibrate");
    g.sample_size(20);
    g.bench_function("schur_100", |bch| {
        bch.iter(|| calibrate_samples(black_box(s100.clone()), &lt, 30.0, Solver::Schur).unwrap())
    });
    g.bench_function("schur_600", |bch| {
        bch.iter(|| calibrate_samples(black_box(s600.clone()), &lt, 30.0, Solver::Schur).unwrap())
    });
    g.sample_size(10);
    g.bench_function("dense_svd_100_one_channel", |bch| {
        bch.iter(|| solve_dense_svd(black_box(&s100), &lt, 30.0, 1).unwrap())
    });
    g.finish();
}

fn six_mp_frames() -> (Vec<Frame>, Response) {
    let b = generate(&SynthOptions {
        width: 2448,
        height: 2448,
        jpeg_quality: None,
        ..SynthOptions::default()
    })
    .unwrap();
    let r = Response::from_curves(b.true_g.clone()).unwrap();
    (b.frames, r)
}

/// Reads every input byte once and writes one f32 per sample: the memory traffic any merge
/// must pay, parallelised like the merge.
fn memory_floor(frames: &[Frame], out: &mut [f32]) {
    let srcs: Vec<&[u8]> = frames
        .iter()
        .map(|f| match &f.pixels {
            Pixels::U8(v) => v.as_slice(),
            Pixels::U16(_) => unreachable!("8-bit bench frames"),
        })
        .collect();
    let band = 3 * 2448 * 16;
    let body = |(k, o): (usize, &mut [f32])| {
        let r = k * band..k * band + o.len();
        let (a, b, c) = (&srcs[0][r.clone()], &srcs[1][r.clone()], &srcs[2][r]);
        for (((v, &a), &b), &c) in o.iter_mut().zip(a).zip(b).zip(c) {
            *v = (a as u32 + b as u32 + c as u32) as f32;
        }
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(band).enumerate().for_each(body);
    }
    #[cfg(not(feature = "parallel"))]
    out.chunks_mut(band).enumerate().for_each(body);
}

/// A straightforward merge: per pixel and frame, hat weight, `g(Z) − ln Δt` with `ln`
/// evaluated each time, `exp` from std; one thread.
fn naive(frames: &[Frame], r: &Response, out: &mut [f32]) {
    for (i, o) in out.iter_mut().enumerate() {
        let c = i % 3;
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for f in frames {
            let Pixels::U8(v) = &f.pixels else { continue };
            let z = v[i];
            let w = if z <= 127 { z as f64 } else { 255.0 - z as f64 };
            num += w * (r.curve(c)[z as usize] - f.exposure.relative().ln());
            den += w;
        }
        *o = if den > 0.0 {
            (num / den).exp() as f32
        } else {
            0.0
        };
    }
}

fn merging(c: &mut Criterion) {
    let (frames, r) = six_mp_frames();
    let mut out = vec![0f32; frames[0].pixels.len()];
    let mut g = c.benchmark_group("merge_6mp");
    g.sample_size(10);
    // A fresh output each time, as `merge` returns it: includes the page faults of 72 MB.
    g.bench_function("lut", |b| {
        b.iter(|| merge(black_box(&frames), &r, &MergeOptions::default()).unwrap())
    });
    g.bench_function("memory_floor", |b| {
        b.iter(|| {
            let mut o = vec![0f32; frames[0].pixels.len()];
            memory_floor(black_box(&frames), &mut o);
            o
        })
    });
    // The output buffer reused, as `merge_into` allows.
    let mut m = merge(&frames, &r, &MergeOptions::default()).unwrap();
    g.bench_function("lut_into", |b| {
        b.iter(|| merge_into(black_box(&frames), &r, &MergeOptions::default(), &mut m).unwrap())
    });
    g.bench_function("memory_floor_into", |b| {
        b.iter(|| memory_floor(black_box(&frames), &mut out))
    });
    let o = MergeOptions {
        confidence: true,
        clipped_mask: true,
        ..Default::default()
    };
    let mut mc = merge(&frames, &r, &o).unwrap();
    g.bench_function("lut_into_with_confidence_and_mask", |b| {
        b.iter(|| merge_into(black_box(&frames), &r, &o, &mut mc).unwrap())
    });
    // The noise-aware merge: the hat pass, the noise model's estimate and the refinement.
    let on = MergeOptions {
        weighting: skydome::merge::Weighting::Noise,
        ..Default::default()
    };
    let mut mn = merge(&frames, &r, &on).unwrap();
    g.bench_function("noise_into", |b| {
        b.iter(|| merge_into(black_box(&frames), &r, &on, &mut mn).unwrap())
    });
    // The same with the noise model given (a camera profile's): the refinement alone.
    let og = MergeOptions {
        noise: Some(skydome::noise::estimate(&frames, &r, 0, None).model),
        ..on
    };
    let mut mg = merge(&frames, &r, &og).unwrap();
    g.bench_function("noise_given_into", |b| {
        b.iter(|| merge_into(black_box(&frames), &r, &og, &mut mg).unwrap())
    });
    g.bench_function("naive", |b| {
        b.iter(|| naive(black_box(&frames), &r, &mut out))
    });
    g.finish();
}

criterion_group! {
    name = benches;
    // criterion's HTML plots need a system font this workspace does not register; the numbers
    // are printed either way.
    config = Criterion::default().without_plots();
    targets = calibration, merging
}
criterion_main!(benches);
