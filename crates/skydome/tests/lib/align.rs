//! Translation alignment (median threshold bitmaps) on synthetic shifts with known truth and on
//! the real hand-held bracket in ../shared/data/banterle_alignment.
use crate::common;
use crate::common::{data_dir, load_jpegs};

use skydome::align::{align, apply_shifts, AlignOptions, Alignment};
use skydome::bracket::Frame;
use skydome::merge::{merge, MergeOptions};
use skydome::response::{calibrate, CalibrateOptions, Response};
use skydome::synth::{generate, SynthOptions};

/// `frame` with its content moved by `(dx, dy)` pixels (edges repeated).
fn shifted(f: &Frame, dx: i32, dy: i32) -> Frame {
    let a = Alignment {
        reference: 0,
        shifts: vec![(-dx, -dy)],
    };
    apply_shifts(std::slice::from_ref(f), &a).remove(0)
}

#[test]
fn known_synthetic_shifts_are_recovered_exactly() {
    for (seed, fisheye, shifts) in [
        (1u64, false, [(5, -3), (-7, 2)]),
        (2, false, [(0, 11), (13, -1)]),
        (3, true, [(-4, -4), (6, 9)]),
    ] {
        let b = generate(&SynthOptions {
            width: 320,
            height: 256,
            seed,
            fisheye,
            // One stop apart, so every frame keeps structure on both sides of its median.
            evs: vec![-1.0, 0.0, 1.0],
            jpeg_quality: Some(90),
            ..SynthOptions::default()
        })
        .unwrap();
        // Frame 1 is the reference; frames 0 and 2 move.
        let mut frames = b.frames.clone();
        frames[0] = shifted(&b.frames[0], shifts[0].0, shifts[0].1);
        frames[2] = shifted(&b.frames[2], shifts[1].0, shifts[1].1);
        let a = align(&frames, &AlignOptions::default());
        println!("seed {seed}: truth {shifts:?}, found {:?}", a.shifts);
        assert_eq!(a.reference, 1);
        assert_eq!(a.shifts, vec![shifts[0], (0, 0), shifts[1]]);
        // An unshifted bracket stays put.
        let a0 = align(&b.frames, &AlignOptions::default());
        assert_eq!(a0.shifts, vec![(0, 0); 3]);
    }
}

/// With `even` (a RAW bracket's frames, demosaiced from one colour filter array) every shift is
/// even, so the mosaic's phase is kept: an even true shift is found exactly, an odd one as an
/// even neighbour (within 1 pixel in each direction).
#[test]
fn even_shifts_keep_a_mosaic_phase() {
    let b = generate(&SynthOptions {
        width: 320,
        height: 256,
        seed: 4,
        evs: vec![-1.0, 0.0, 1.0],
        jpeg_quality: Some(90),
        ..SynthOptions::default()
    })
    .unwrap();
    let even = AlignOptions {
        even: true,
        ..AlignOptions::default()
    };
    for shifts in [[(4, -6), (-10, 2)], [(5, -3), (-7, 2)], [(1, 1), (-3, 0)]] {
        let mut frames = b.frames.clone();
        frames[0] = shifted(&b.frames[0], shifts[0].0, shifts[0].1);
        frames[2] = shifted(&b.frames[2], shifts[1].0, shifts[1].1);
        let plain = align(&frames, &AlignOptions::default());
        let a = align(&frames, &even);
        println!(
            "truth {shifts:?}: found {:?}, even {:?}",
            plain.shifts, a.shifts
        );
        assert_eq!(plain.shifts, vec![shifts[0], (0, 0), shifts[1]]);
        for (&(fx, fy), &(tx, ty)) in [a.shifts[0], a.shifts[2]].iter().zip(&shifts) {
            assert!(fx % 2 == 0 && fy % 2 == 0, "{:?}", a.shifts);
            assert!(
                (fx - tx).abs() <= 1 && (fy - ty).abs() <= 1,
                "{:?}",
                a.shifts
            );
            if tx % 2 == 0 && ty % 2 == 0 {
                assert_eq!((fx, fy), (tx, ty));
            }
        }
        assert_eq!(a.shifts[1], (0, 0));
    }
}

/// The worst frame's median `|log2(E_frame / E_merged)|` ([`common::frame_consistency`]).
fn worst_frame_consistency(frames: &[Frame], r: &Response) -> f64 {
    let m = merge(frames, r, &MergeOptions::default()).unwrap();
    common::frame_consistency(frames, r, &m.radiance)
        .into_iter()
        .fold(0.0, f64::max)
}

#[test]
fn hand_held_real_bracket_agrees_better_once_aligned() {
    let Some(d) = data_dir() else { return };
    let frames = load_jpegs(
        &d.join("banterle_alignment"),
        &[
            ("IMG_4209.jpg", 1.0 / 80.0),
            ("IMG_4210.jpg", 1.0 / 320.0),
            ("IMG_4211.jpg", 1.0 / 20.0),
        ],
    );
    let a = align(&frames, &AlignOptions::default());
    println!("banterle_alignment shifts: {:?}", a.shifts);
    assert!(a.largest() >= 1 && a.largest() <= 64, "{a:?}");
    let aligned = apply_shifts(&frames, &a);
    let before = {
        let cal = calibrate(&frames, None, &CalibrateOptions::default()).unwrap();
        worst_frame_consistency(&frames, &cal.response)
    };
    let after = {
        let cal = calibrate(&aligned, None, &CalibrateOptions::default()).unwrap();
        worst_frame_consistency(&aligned, &cal.response)
    };
    println!("worst-frame median |log2(E_frame / E_merged)|: {before:.3} → {after:.3} stops");
    assert!(after < 0.7 * before, "{before} → {after}");
    // Aligning twice finds nothing left to do.
    let again = align(&aligned, &AlignOptions::default());
    assert!(again.largest() <= 1, "{again:?}");
}
