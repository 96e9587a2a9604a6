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
    let (f0, f1, f2, times) = (
        b("frame_0.jpg"),
        b("frame_1.jpg"),
        b("frame_2.jpg"),
        b("times.txt"),
    );
    // Every step reads the bundled bracket the same way.
    let bracket_args = [f0.as_str(), &f1, &f2, "--times-file", &times];

    let step = |args: &[&str]| -> Result<()> {
        let mut full = vec!["skydome"];
        full.extend_from_slice(args);
        // `info` and `compare` write nothing, so they take no --force.
        if a.force && !matches!(args.first(), Some(&"info" | &"compare")) {
            full.push("--force");
        }
        if quiet {
            full.push("--quiet");
        }
        if !quiet {
            crate::out(&format!("\n$ {}", full.join(" ")));
        }
        crate::run_args(&full)
    };
    let with_bracket = |cmd: &str, rest: &[&str]| -> Result<()> {
        step(&[&[cmd][..], &bracket_args, rest].concat())
    };

    // 1. The lens: detect the image circle; the bundled bracket was shot through an equidistant 235° lens.
    let (lens_json, lens_overlay) = (p("lens.json"), p("lens_overlay.png"));
    step(
        &[
            &["lens", "detect"][..],
            &bracket_args,
            &[
                "--model",
                "equidistant",
                "--fov",
                "235",
                "-o",
                &lens_json,
                "--overlay",
                &lens_overlay,
            ],
        ]
        .concat(),
    )?;
    let lens = crate::geometry::read_lens(&dir.join("lens.json"))?;
    let c = lens.circle;
    let circle = format!("{:.3},{:.3},{:.3}", c.cx, c.cy, c.r);

    // 2. Calibrate the camera response once, sampling inside the circle. 600 samples: the
    // bundled sky has few dark pixels (only the ground ring), and with the default 128 the
    // toe of the curve below code ≈ 90 changes from seed to seed (RMS spread 0.25 ln units
    // over 5 seeds; 0.035 with 600, below the 0.05 threshold).
    let camera = p("camera.json");
    with_bracket(
        "calibrate",
        &[
            "--circle",
            &circle,
            "--samples",
            "600",
            "--repeat",
            "5",
            "-o",
            &camera,
            "--plot",
            &p("response.png"),
        ],
    )?;

    // 3. Merge with the profile, crop to the 180° dome, find the sun, mark north, make maps.
    let (sky, latlong) = (p("sky.hdr"), p("sky_latlong.hdr"));
    with_bracket(
        "merge",
        &[
            "--profile",
            &camera,
            "--lens",
            &lens_json,
            "--crop",
            "--north",
            "0",
            "--sun",
            "auto",
            "-o",
            &sky,
            "--exr",
            &p("sky.exr"),
            "--preview",
            &p("preview.jpg"),
            "--overlay",
            &p("overlay.png"),
            "--equirect",
            &latlong,
        ],
    )?;

    // 4. Accuracy against the ground truth the bracket was rendered from (uncropped merge),
    // inside the 180° horizon, after one scale per channel (a response is known up to one
    // constant per channel, so a bracket alone fixes white balance only up to that constant).
    let full = p("full.hdr");
    with_bracket("merge", &["--profile", &camera, "-o", &full])?;
    let horizon = lens.radius_at_deg(90.0).context("lens")?;
    let dome = format!("{:.3},{:.3},{:.3}", c.cx, c.cy, horizon);
    step(&[
        "compare",
        &full,
        &b("truth.hdr"),
        "--per-channel",
        "--circle",
        &dome,
    ])?;

    // 5. Pictures.
    step(&[
        "tonemap",
        &sky,
        "-o",
        &p("tonemap_minmax.png"),
        "--op",
        "minmax",
    ])?;
    step(&["falsecolor", &sky, "-o", &p("falsecolor.png")])?;
    step(&["histogram", &sky, "-o", &p("histogram.png")])?;
    step(&["render", &latlong, "-o", &p("spheres.png")])?;
    step(&["info", &sky])?;
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
