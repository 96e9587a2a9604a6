//! The synthetic bracket generator: the ground truth other tests rely on.

use skydome::bracket::Pixels;
use skydome::synth::{generate, SynthOptions, SUN_RADIANCE};

fn small() -> SynthOptions {
    SynthOptions {
        width: 256,
        height: 256,
        ..SynthOptions::default()
    }
}

#[test]
fn same_seed_gives_the_same_bracket_and_another_seed_does_not() {
    let a = generate(&small()).unwrap();
    let b = generate(&small()).unwrap();
    let c = generate(&SynthOptions { seed: 2, ..small() }).unwrap();
    assert_eq!(a.truth, b.truth);
    assert_eq!(a.frames, b.frames);
    assert_ne!(a.frames[1].pixels, c.frames[1].pixels);
}

#[test]
fn scene_spans_more_than_16_stops_inside_the_circle() {
    let b = generate(&small()).unwrap();
    let circle = b.circle.unwrap();
    let (mut lo, mut hi) = (f32::MAX, 0f32);
    for y in 0..b.truth.height {
        for x in 0..b.truth.width {
            let p = b.truth.pixel(x, y);
            if circle.contains_pixel(x, y) {
                for v in p {
                    assert!(v > 0.0 && v.is_finite());
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            } else {
                assert_eq!(p, [0.0; 3], "housing must be black");
            }
        }
    }
    let stops = (hi / lo).log2();
    println!("range inside the circle: {stops:.1} stops");
    assert!(stops >= 16.0);
    assert_eq!(hi, SUN_RADIANCE);
}

#[test]
fn sun_is_saturated_in_every_frame_and_frames_are_sorted() {
    let b = generate(&small()).unwrap();
    let sun: Vec<usize> = (0..b.truth.pixel_count())
        .filter(|&p| b.truth.data[3 * p] == SUN_RADIANCE)
        .collect();
    assert!(!sun.is_empty());
    for f in &b.frames {
        let Pixels::U8(v) = &f.pixels else {
            panic!("8-bit frames")
        };
        // The disc's centre pixel is far from JPEG ringing at its rim.
        let mid = sun[sun.len() / 2];
        assert!(
            v[3 * mid..3 * mid + 3].iter().all(|&z| z >= 250),
            "{}",
            f.name
        );
    }
    let t: Vec<f64> = b.frames.iter().map(|f| f.exposure.time_s).collect();
    assert!(t.windows(2).all(|w| w[1] > w[0]));
    assert!((t[1] / t[0] - 4.0).abs() < 1e-12);
}

#[test]
fn true_curves_increase_and_differ_per_channel() {
    let b = generate(&small()).unwrap();
    for g in &b.true_g {
        assert_eq!(g.len(), 256);
        assert!(g.windows(2).all(|w| w[1] > w[0]));
        assert!(g[255].abs() < 1e-12, "code 255 is X = 1");
    }
    let most = (1..256)
        .map(|z| (b.true_g[0][z] - b.true_g[2][z]).abs())
        .fold(0.0, f64::max);
    assert!(most > 0.5, "red and blue curves differ by at most {most}");
}

#[test]
fn frames_follow_the_true_response_without_noise_or_jpeg() {
    let o = SynthOptions {
        jpeg_quality: None,
        shot_noise: false,
        read_noise: 0.0,
        ..small()
    };
    let b = generate(&o).unwrap();
    for f in &b.frames {
        let Pixels::U8(v) = &f.pixels else {
            panic!("8-bit frames")
        };
        let gain = f.exposure.time_s * b.exposure_scale;
        for (i, (&l, &z)) in b.truth.data.iter().zip(v).enumerate() {
            let want = (255.0 * o.crf[i % 3].forward((l as f64 * gain).min(1.0))).round() as u8;
            assert_eq!(z, want);
        }
    }
}

#[test]
fn noise_and_jpeg_perturb_but_do_not_bias_mid_tones() {
    let clean = generate(&SynthOptions {
        jpeg_quality: None,
        shot_noise: false,
        read_noise: 0.0,
        ..small()
    })
    .unwrap();
    let noisy = generate(&SynthOptions {
        full_well: 4000.0,
        read_noise: 3.0,
        jpeg_quality: Some(90),
        ..small()
    })
    .unwrap();
    let (Pixels::U8(a), Pixels::U8(b)) = (&clean.frames[1].pixels, &noisy.frames[1].pixels) else {
        panic!("8-bit frames")
    };
    // Near black, noise clipped at zero and the steep toe of the response do bias the codes
    // upwards, as in a real camera; mid-tones must stay unbiased.
    let diff: Vec<f64> = a
        .iter()
        .zip(b)
        .filter(|(&x, _)| (30..=225).contains(&x))
        .map(|(&x, &y)| y as f64 - x as f64)
        .collect();
    let n = diff.len() as f64;
    assert!(n > 10_000.0);
    let mean = diff.iter().sum::<f64>() / n;
    let rms = (diff.iter().map(|d| d * d).sum::<f64>() / n).sqrt();
    println!("noisy − clean: mean {mean:.3} codes, rms {rms:.3} codes");
    assert!(rms > 1.0, "noise must be visible");
    assert!(mean.abs() < 0.5, "noise must be unbiased");
}
