//! One noise-aware merge of random 8-bit frames, as `merge::fused`'s test makes them, and the
//! FNV-1a digest of the radiance's bits (see run.mjs).

use skydome::bracket::{Exposure, Frame, Pixels};
use skydome::merge::{merge, MergeOptions, Weighting};
use skydome::noise::NoiseModel;
use skydome::response::{Response, LEVELS};

/// `p` random frames of `w × h` (a third of the codes at the black level, the top fade or a
/// bound), 1.5 stops apart.
fn frames(p: usize, w: usize, h: usize, seed: u64) -> Vec<Frame> {
    let mut state = seed | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    (0..p)
        .map(|j| {
            let pixels = (0..w * h * 3)
                .map(|_| match next() % 9 {
                    0 => 0,
                    1 => 255,
                    2 => 240 + (next() % 16) as u8,
                    3 => (next() % 16) as u8,
                    _ => next() as u8,
                })
                .collect();
            Frame {
                name: format!("f{j}"),
                width: w,
                height: h,
                pixels: Pixels::U8(pixels),
                exposure: Exposure {
                    time_s: 2f64.powf(1.5 * j as f64) / 100.0,
                    iso: None,
                    f_number: None,
                },
            }
        })
        .collect()
}

/// The digest of the noise-aware merge of `p` frames of `w × h` with black level `black`
/// (0 when the merge fails).
#[no_mangle]
pub extern "C" fn merge_digest(p: usize, black: u8, w: usize, h: usize) -> u64 {
    let Ok(r) = Response::from_curves([0.9, 1.0, 1.1].map(|a| {
        (0..LEVELS)
            .map(|z| a * ((z as f64 + 0.5) / 128.5).ln())
            .collect::<Vec<_>>()
    })) else {
        return 0;
    };
    let fs = frames(p, w, h, 7 + p as u64 + black as u64 + w as u64);
    let o = MergeOptions {
        weighting: Weighting::Noise,
        noise: Some(NoiseModel::default()),
        black_level: black,
        ..Default::default()
    };
    let Ok(m) = merge(&fs, &r, &o) else {
        return 0;
    };
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for v in &m.radiance.data {
        for b in v.to_bits().to_le_bytes() {
            h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}
