//! The noise-model merge's cost against the hat merge's (issue 27: at most 1.3×), in CPU time.
//!
//! For synthetic lossless 8-bit fish-eye brackets of 6 MP (2448²) and 12 MP (3464²) at 3, 5
//! and 9 frames (2 stops apart, the true curve), calls in turn, `CALLS` times each:
//! `merge_into` with [`Weighting::Hat`] (the default), with [`Weighting::Noise`] and the noise
//! model given (a camera profile's), [`noise::estimate`] alone (the fit from the frames), and
//! `merge_into` with [`Weighting::Noise`] fitting the model itself. Each call's CPU time is the
//! sum over all of the process's threads (Linux `/proc/self/task/*/schedstat`), so other
//! processes on the machine inflate wall time but not these figures; medians and the ratios to
//! the hat's median are printed. Wall time is printed beside them.
//!
//! Run: `cargo bench -p skydome --bench noise_cost` (`SKYDOME_COST_CALLS`, default 9;
//! `SKYDOME_COST_CASES`, e.g. `6:3,12:3`, default all six; `SKYDOME_COST_ONLY`, one of `hat`,
//! `given`, `fit`, `with-fit`, calls only that one, e.g. to count its instructions with
//! `valgrind --tool=callgrind` — the others' columns then read 0). A size other than 6 or 12 MP
//! is a square of about that many pixels: `SKYDOME_COST_CASES=1:3` is 1000² at 3 frames.

use skydome::bracket::Frame;
use skydome::merge::{merge, merge_into, MergeOptions, Weighting};
use skydome::noise;
use skydome::response::Response;
use skydome::synth::{generate, SynthOptions};
use std::hint::black_box;
use std::time::Instant;

/// CPU time of all of this process's threads so far, nanoseconds (0 where it cannot be read).
fn cpu_ns() -> u64 {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return 0;
    };
    dir.filter_map(|e| e.ok())
        .filter_map(|e| std::fs::read_to_string(e.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

fn bracket(side: usize, frames: usize) -> (Vec<Frame>, Response) {
    let evs: Vec<f64> = (0..frames)
        .map(|k| 2.0 * k as f64 - (frames - 1) as f64)
        .collect();
    let b = generate(&SynthOptions {
        width: side,
        height: side,
        evs,
        jpeg_quality: None,
        ..SynthOptions::default()
    })
    .expect("synthetic bracket");
    let r = Response::from_curves(b.true_g.clone()).expect("true curve");
    (b.frames, r)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    // `cargo bench` passes `--bench`; any other argument is a filter this harness ignores.
    let calls: usize = std::env::var("SKYDOME_COST_CALLS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(9)
        .max(1);
    let cases: Vec<(usize, usize)> = std::env::var("SKYDOME_COST_CASES")
        .ok()
        .map(|s| {
            s.split(',')
                .filter_map(|c| {
                    let (a, b) = c.split_once(':')?;
                    Some((a.trim().parse().ok()?, b.trim().parse().ok()?))
                })
                .collect()
        })
        .unwrap_or_else(|| vec![(6, 3), (6, 5), (6, 9), (12, 3), (12, 5), (12, 9)]);
    let only = std::env::var("SKYDOME_COST_ONLY").ok().map(|s| {
        ["hat", "given", "fit", "with-fit"]
            .iter()
            .position(|&n| n == s)
            .expect("SKYDOME_COST_ONLY: hat, given, fit or with-fit")
    });
    println!(
        "| case | hat | noise, model given | fit alone | noise with its fit | (wall: hat, given, with fit) |"
    );
    println!("|---|---|---|---|---|---|");
    for (mp, p) in cases {
        // 6 and 12 MP as documented; any other size (e.g. 1, for counting instructions under
        // valgrind, where generating 6 MP takes minutes) as a square of about that many pixels.
        let side = match mp {
            12 => 3464,
            6 => 2448,
            m => ((m as f64 * 1e6).sqrt() as usize).max(8) / 8 * 8,
        };
        let (frames, r) = bracket(side, p);
        let hat = MergeOptions::default();
        let fit = MergeOptions {
            weighting: Weighting::Noise,
            ..Default::default()
        };
        let model = noise::estimate(&frames, &r, 0, None).model;
        let given = MergeOptions {
            noise: Some(model),
            ..fit
        };
        let mut out = merge(&frames, &r, &hat).expect("merge");
        // [cpu ms; 4], [wall ms; 4]
        let mut cpu: [Vec<f64>; 4] = Default::default();
        let mut wall: [Vec<f64>; 4] = Default::default();
        for _ in 0..calls + 1 {
            for (k, (c, w)) in cpu.iter_mut().zip(wall.iter_mut()).enumerate() {
                if only.is_some_and(|o| o != k) {
                    c.push(0.0);
                    w.push(0.0);
                    continue;
                }
                let (t0, c0) = (Instant::now(), cpu_ns());
                match k {
                    0 => merge_into(black_box(&frames), &r, &hat, &mut out).expect("hat"),
                    1 => merge_into(black_box(&frames), &r, &given, &mut out).expect("given"),
                    2 => {
                        black_box(noise::estimate(black_box(&frames), &r, 0, None));
                    }
                    _ => merge_into(black_box(&frames), &r, &fit, &mut out).expect("fit"),
                }
                c.push((cpu_ns() - c0) as f64 / 1e6);
                w.push(t0.elapsed().as_secs_f64() * 1e3);
            }
        }
        // The first round warms the caches and the allocator: dropped.
        let m: Vec<f64> = cpu.iter_mut().map(|v| median(&mut v[1..])).collect();
        let mw: Vec<f64> = wall.iter_mut().map(|v| median(&mut v[1..])).collect();
        println!(
            "| {mp} MP, {p} frames | {:.0} ms | {:.0} ms ({:.2}×) | {:.0} ms ({:.2}×) | {:.0} ms ({:.2}×) | {:.0} / {:.0} / {:.0} ms |",
            m[0],
            m[1],
            m[1] / m[0],
            m[2],
            m[2] / m[0],
            m[3],
            m[3] / m[0],
            mw[0],
            mw[1],
            mw[3]
        );
    }
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "({calls} alternating calls each, medians of CPU time of all threads; load average {})",
        load.split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" ")
    );
}
