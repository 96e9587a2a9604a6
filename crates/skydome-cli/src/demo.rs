//! `skydome demo [-o DIR]`: the whole pipeline on the small synthetic fish-eye bracket bundled in
//! the binary (made by `skydome synth --size 400 --quality 90`, see `demo/` in the repository),
//! printing each equivalent command as it runs it.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use crate::io::Outputs;

/// The bundled bracket: three frames at EV −2, 0, +2, their times, and the true radiance.
const FILES: [(&str, &[u8]); 5] = [
    ("frame_0.jpg", include_bytes!("../../../demo/frame_0.jpg")),
    ("frame_1.jpg", include_bytes!("../../../demo/frame_1.jpg")),
    ("frame_2.jpg", include_bytes!("../../../demo/frame_2.jpg")),
    ("times.txt", include_bytes!("../../../demo/times.txt")),
    ("truth.hdr", include_bytes!("../../../demo/truth.hdr")),
];

/// Arguments of `skydome demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Folder to write into (created when missing).
    #[arg(short, long, default_value = "skydome-demo")]
    pub output: PathBuf,
    /// Replace files from an earlier demo run.
    #[arg(long)]
    pub force: bool,
}

/// The top-level entry point for `skydome demo`.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    let dir = &a.output;
    let bracket = dir.join("bracket");
    std::fs::create_dir_all(&bracket)
        .with_context(|| format!("{}: cannot create", bracket.display()))?;
    let mut out = Outputs::default();
    for (name, bytes) in FILES {
        out.add(&bracket.join(name), bytes.to_vec());
    }
    out.commit(&[], a.force)?;
    let p = |name: &str| dir.join(name).display().to_string();
    let b = |name: &str| bracket.join(name).display().to_string();
    let frames = [b("frame_0.jpg"), b("frame_1.jpg"), b("frame_2.jpg")];
    let times = ["--times-file".to_string(), b("times.txt")];
    let force: &[&str] = if a.force { &["--force"] } else { &[] };
    let quiet_flag: &[&str] = if quiet { &["--quiet"] } else { &[] };

    let step = |args: Vec<String>| -> Result<()> {
        let mut full = vec!["skydome".to_string()];
        full.extend(args);
        full.extend(force.iter().map(|s| s.to_string()));
        full.extend(quiet_flag.iter().map(|s| s.to_string()));
        if !quiet {
            crate::out(&format!("\n$ {}", full.join(" ")));
        }
        crate::run_args(&full)
    };
    let strs = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();

    // 1. The lens: detect the image circle; the bundled bracket was shot through an equidistant 235° lens.
    step(
        [
            strs(&["lens", "detect"]),
            frames.to_vec(),
            times.to_vec(),
            strs(&["--model", "equidistant", "--fov", "235", "-o"]),
            vec![p("lens.json")],
            strs(&["--overlay"]),
            vec![p("lens_overlay.png")],
        ]
        .concat(),
    )?;
    let lens = crate::geometry::read_lens(&dir.join("lens.json"))?;
    let c = lens.circle;
    let circle = format!("{:.3},{:.3},{:.3}", c.cx, c.cy, c.r);

    // 2. Calibrate the camera response once, sampling inside the circle.
    step(
        [
            strs(&["calibrate"]),
            frames.to_vec(),
            times.to_vec(),
            strs(&["--circle", &circle, "--repeat", "5", "-o"]),
            vec![p("camera.json"), "--plot".into(), p("response.png")],
        ]
        .concat(),
    )?;

    // 3. Merge with the profile, crop to the 180° dome, find the sun, mark north, make maps.
    step(
        [
            strs(&["merge"]),
            frames.to_vec(),
            times.to_vec(),
            strs(&["--profile"]),
            vec![p("camera.json")],
            strs(&["--lens"]),
            vec![p("lens.json")],
            strs(&["--crop", "--north", "0", "--sun", "auto", "-o"]),
            vec![
                p("sky.hdr"),
                "--exr".into(),
                p("sky.exr"),
                "--preview".into(),
                p("preview.jpg"),
                "--overlay".into(),
                p("overlay.png"),
                "--equirect".into(),
                p("sky_latlong.hdr"),
            ],
        ]
        .concat(),
    )?;

    // 4. Accuracy against the ground truth the bracket was rendered from (uncropped merge).
    step(
        [
            strs(&["merge"]),
            frames.to_vec(),
            times.to_vec(),
            strs(&["--profile"]),
            vec![p("camera.json"), "-o".into(), p("full.hdr")],
        ]
        .concat(),
    )?;
    // Inside the 180° horizon, after one scale per channel (a response is known up to one
    // constant per channel, so a bracket alone fixes white balance only up to that constant).
    let horizon = lens.radius_at_deg(90.0).context("lens")?;
    let dome = format!("{:.3},{:.3},{:.3}", c.cx, c.cy, horizon);
    step(
        [
            strs(&["compare"]),
            vec![
                p("full.hdr"),
                b("truth.hdr"),
                "--per-channel".into(),
                "--circle".into(),
                dome,
            ],
        ]
        .concat(),
    )?;

    // 5. Pictures.
    step(
        [
            strs(&["tonemap"]),
            vec![p("sky.hdr"), "-o".into(), p("tonemap_minmax.png")],
            strs(&["--op", "minmax"]),
        ]
        .concat(),
    )?;
    step(
        [
            strs(&["falsecolor"]),
            vec![p("sky.hdr"), "-o".into(), p("falsecolor.png")],
        ]
        .concat(),
    )?;
    step(
        [
            strs(&["histogram"]),
            vec![p("sky.hdr"), "-o".into(), p("histogram.png")],
        ]
        .concat(),
    )?;
    step(
        [
            strs(&["render"]),
            vec![p("sky_latlong.hdr"), "-o".into(), p("spheres.png")],
        ]
        .concat(),
    )?;
    step([strs(&["info"]), vec![p("sky.hdr")]].concat())?;
    if !dir.join("sky.hdr").is_file() {
        bail!("{}: the demo did not produce sky.hdr", dir.display());
    }
    if !quiet {
        crate::out(&format!(
            "\ndemo finished: open {} and {}",
            p("overlay.png"),
            p("spheres.png")
        ));
    }
    Ok(())
}
