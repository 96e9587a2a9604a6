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

/// The curves every merge here uses: three slightly different logarithms.
fn response() -> Option<Response> {
    Response::from_curves([0.9, 1.0, 1.1].map(|a| {
        (0..LEVELS)
            .map(|z| a * ((z as f64 + 0.5) / 128.5).ln())
            .collect::<Vec<_>>()
    }))
    .ok()
}

/// The FNV-1a digest of a radiance's bits.
fn digest(data: &[f32]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for v in data {
        for b in v.to_bits().to_le_bytes() {
            h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// The noise-aware merge of `frames` with black level `black`, its digest (0 when it fails).
fn merge_noise(frames: &[Frame], r: &Response, black: u8) -> u64 {
    let o = MergeOptions {
        weighting: Weighting::Noise,
        noise: Some(NoiseModel::default()),
        black_level: black,
        ..Default::default()
    };
    merge(frames, r, &o).map_or(0, |m| digest(&m.radiance.data))
}

/// The digest of the noise-aware merge of `p` frames of `w × h` with black level `black`
/// (0 when the merge fails).
#[no_mangle]
pub extern "C" fn merge_digest(p: usize, black: u8, w: usize, h: usize) -> u64 {
    let Some(r) = response() else {
        return 0;
    };
    merge_noise(
        &frames(p, w, h, 7 + p as u64 + black as u64 + w as u64),
        &r,
        black,
    )
}

thread_local! {
    /// The frames of [`prepare`], for timing [`merge_prepared`] alone.
    static PREPARED: std::cell::RefCell<Vec<Frame>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Makes `p` random frames of `w × h` for [`merge_prepared`] (timing: run.mjs `--time`).
#[no_mangle]
pub extern "C" fn prepare(p: usize, w: usize, h: usize) {
    PREPARED.with(|f| *f.borrow_mut() = frames(p, w, h, 99));
}

/// The digest of the noise-aware merge (black level 0) of the frames of [`prepare`].
#[no_mangle]
pub extern "C" fn merge_prepared() -> u64 {
    let Some(r) = response() else {
        return 0;
    };
    PREPARED.with(|f| merge_noise(&f.borrow(), &r, 0))
}
