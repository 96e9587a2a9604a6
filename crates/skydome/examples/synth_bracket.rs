//! Writes a synthetic fish-eye bracket with its ground truth, and skydome's own result on it.
//!
//! ```text
//! cargo run -p skydome --example synth_bracket -- OUTDIR [--size 512] [--seed 1]
//!     [--samples 100] [--lambda 30] [--edge 8] [--quality 92 | --png] [--full-well E] [--read-noise E] [--no-shot-noise]
//!     [--evs -2,0,2] [--base-time S] [--black-level CODE] [--code-bands N] [--weighting hat|noise|none]
//! ```
//!
//! Writes into `OUTDIR`:
//! - `frame_0.png`, `frame_1.png`, …, shortest exposure first: the exact pixels skydome saw
//!   (after the simulated JPEG round trip), stored losslessly so every tool reads the same data;
//! - `times.txt`: `FILE TIME` per line (seconds);
//! - `truth.pfm`: the true radiance (little-endian PFM, bottom row first, as PFM requires);
//! - `true_curves.csv`: `z,g_r,g_g,g_b` with the true `g(z) = ln f⁻¹(z/255)`;
//! - `skydome_merged.pfm`, `skydome_curves.csv`: skydome's calibration (robust sampling,
//!   λ = 30) and merge (hat weighting) of the frames;
//! - `skydome_report.json`: sampling report, curve RMSE and merge metrics against the truth.
//!
//! `scripts/opencv_compare.py` runs OpenCV on the same files and prints both side by side.

use skydome::compare::{compare, well_exposed_mask, CompareOptions};
use skydome::merge::{merge, MergeOptions};
use skydome::response::{calibrate, CalibrateOptions};
use skydome::synth::{generate, SynthOptions};
use std::io::Write;
use std::path::Path;

fn write_pfm(path: &Path, img: &skydome::HdrImage) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    write!(f, "PF\n{} {}\n-1.0\n", img.width, img.height)?;
    for row in img.data.chunks_exact(3 * img.width).rev() {
        for v in row {
            f.write_all(&v.to_le_bytes())?;
        }
    }
    f.flush()
}

fn write_curves(path: &Path, g: &[Vec<f64>; 3]) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(f, "z,g_r,g_g,g_b")?;
    for (z, ((r, gg), b)) in g[0].iter().zip(&g[1]).zip(&g[2]).enumerate() {
        writeln!(f, "{z},{r},{gg},{b}")?;
    }
    f.flush()
}

/// RMS (in stops) of `g_rec − g_true` over z = 10..=245 after removing the mean offset.
fn curve_rmse_stops(rec: &[f64], truth: &[f64]) -> f64 {
    let d: Vec<f64> = (10..=245).map(|z| rec[z] - truth[z]).collect();
    let m = d.iter().sum::<f64>() / d.len() as f64;
    (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
        / std::f64::consts::LN_2
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut out = None;
    let mut opts = SynthOptions::default();
    let mut samples = 100usize;
    let mut lambda = CalibrateOptions::default().lambda;
    let mut edge = None;
    let mut code_bands = skydome::sampling::SampleOptions::default().code_bands;
    let mut weighting = skydome::merge::Weighting::Hat;
    while let Some(a) = args.next() {
        let mut val = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--size" => {
                let s: usize = val()?.parse()?;
                opts.width = s;
                opts.height = s;
            }
            "--seed" => opts.seed = val()?.parse()?,
            "--samples" => samples = val()?.parse()?,
            "--lambda" => lambda = val()?.parse()?,
            "--edge" => edge = Some(val()?.parse()?),
            "--quality" => opts.jpeg_quality = Some(val()?.parse()?),
            "--png" => opts.jpeg_quality = None,
            "--full-well" => opts.full_well = val()?.parse()?,
            "--read-noise" => opts.read_noise = val()?.parse()?,
            "--no-shot-noise" => opts.shot_noise = false,
            "--evs" => {
                opts.evs = val()?
                    .split(',')
                    .map(|v| v.trim().parse())
                    .collect::<Result<_, _>>()?
            }
            "--base-time" => opts.base_time_s = val()?.parse()?,
            "--black-level" => opts.black_level = val()?.parse()?,
            "--code-bands" => code_bands = val()?.parse()?,
            "--weighting" => {
                weighting = val()?
                    .parse()
                    .map_err(|e: skydome::UnknownName| e.to_string())?
            }
            _ if out.is_none() && !a.starts_with("--") => out = Some(a),
            _ => return Err(format!("unknown argument {a}").into()),
        }
    }
    let out = out.ok_or("usage: synth_bracket OUTDIR [--size N] [--seed S] [--samples N] [--lambda L] [--edge CODES] [--quality Q | --png] [--full-well E] [--read-noise E] [--no-shot-noise] [--evs A,B,..] [--base-time S] [--black-level CODE] [--code-bands N] [--weighting hat|noise|none]")?;
    let dir = Path::new(&out);
    std::fs::create_dir_all(dir)?;
    let b = generate(&opts)?;
    let mut times = String::new();
    for (j, f) in b.frames.iter().enumerate() {
        let name = format!("frame_{j}.png");
        let skydome::bracket::Pixels::U8(px) = &f.pixels else {
            return Err("synthetic frames are 8-bit".into());
        };
        let img = image::RgbImage::from_raw(f.width as u32, f.height as u32, px.clone())
            .ok_or("frame buffer size")?;
        img.save_with_format(dir.join(&name), image::ImageFormat::Png)?;
        times.push_str(&format!("{name} {}\n", f.exposure.time_s));
    }
    std::fs::write(dir.join("times.txt"), times)?;
    write_pfm(&dir.join("truth.pfm"), &b.truth)?;
    write_curves(&dir.join("true_curves.csv"), &b.true_g)?;

    let mut co = CalibrateOptions::default();
    co.sampling.samples = samples;
    co.lambda = lambda;
    if let Some(e) = edge {
        co.sampling.edge_threshold = e;
    }
    co.sampling.code_bands = code_bands;
    let cal = calibrate(&b.frames, b.circle, &co)?;
    let merged = merge(
        &b.frames,
        &cal.response,
        &MergeOptions {
            weighting,
            black_level: opts.black_level.round() as u8,
            ..MergeOptions::default()
        },
    )?;
    write_pfm(&dir.join("skydome_merged.pfm"), &merged.radiance)?;
    write_curves(&dir.join("skydome_curves.csv"), cal.response.curves())?;
    let mask = well_exposed_mask(&b.frames, 10, 245)?;
    let report = compare(
        &merged.radiance,
        &b.truth,
        Some(&mask),
        &CompareOptions {
            per_channel_scale: true,
        },
    )?;
    let rmse: Vec<f64> = (0..3)
        .map(|c| curve_rmse_stops(cal.response.curve(c), &b.true_g[c]))
        .collect();
    let json = serde_json::json!({
        "lambda": lambda,
        "sampling": cal.report(),
        "curve_rmse_stops": rmse,
        "merge_vs_truth": report,
    });
    std::fs::write(
        dir.join("skydome_report.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}
