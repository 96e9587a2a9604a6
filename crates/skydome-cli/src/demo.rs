//! `skydome demo [-o DIR]`: the whole pipeline on the small synthetic fish-eye bracket bundled in
//! the binary (made by `skydome synth --size 400 --quality 90`, see `demo/` in the repository),
//! printing each equivalent command as it runs it.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use skydome::fisheye::LensProfile;

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
    let d = Demo::new(&a, quiet)?;
    let lens = d.lens()?;
    let camera = d.calibrate(&lens)?;
    d.merge(&camera)?;
    d.compare(&camera, &lens)?;
    d.pictures()?;
    if !a.output.join("sky.hdr").is_file() {
        bail!("{}: the demo did not produce sky.hdr", a.output.display());
    }
    if !quiet {
        crate::out(&format!(
            "\ndemo finished: open {} and {}",
            d.out("overlay.png"),
            d.out("spheres.png")
        ));
    }
    Ok(())
}

/// The demo's folders and the way it runs each command.
struct Demo {
    dir: PathBuf,
    bracket: PathBuf,
    force: bool,
    quiet: bool,
}

impl Demo {
    /// Writes the bundled bracket into `DIR/bracket`.
    fn new(a: &Args, quiet: bool) -> Result<Self> {
        let bracket = a.output.join("bracket");
        std::fs::create_dir_all(&bracket)
            .with_context(|| format!("{}: cannot create", bracket.display()))?;
        let mut out = Outputs::default();
        for (name, bytes) in FILES {
            out.add(&bracket.join(name), bytes.to_vec());
        }
        out.commit(&[], a.force)?;
        Ok(Self {
            dir: a.output.clone(),
            bracket,
            force: a.force,
            quiet,
        })
    }

    /// An output path, as text.
    fn out(&self, name: &str) -> String {
        self.dir.join(name).display().to_string()
    }

    /// A file of the bundled bracket, as text.
    fn input(&self, name: &str) -> String {
        self.bracket.join(name).display().to_string()
    }

    /// Runs one command as a user would type it, printing it first.
    fn step(&self, args: &[&str]) -> Result<()> {
        let mut full = vec!["skydome"];
        full.extend_from_slice(args);
        // `info` and `compare` write nothing, so they take no --force.
        if self.force && !matches!(args.first(), Some(&"info" | &"compare")) {
            full.push("--force");
        }
        if self.quiet {
            full.push("--quiet");
        } else {
            crate::out(&format!("\n$ {}", full.join(" ")));
        }
        crate::run_args(&full)
    }

    /// Runs `cmd` on the bundled bracket (every step reads it the same way) with `rest`.
    fn with_bracket(&self, cmd: &[&str], rest: &[&str]) -> Result<()> {
        let frames: Vec<String> = (0..3)
            .map(|i| self.input(&format!("frame_{i}.jpg")))
            .collect();
        let times = self.input("times.txt");
        let bracket = [&frames[0], &frames[1], &frames[2], "--times-file", &times];
        self.step(&[cmd, &bracket[..], rest].concat())
    }

    /// Step 1, the lens: detect the image circle; the bundled bracket was shot through an
    /// equidistant 235° lens.
    fn lens(&self) -> Result<LensProfile> {
        let (json, overlay) = (self.out("lens.json"), self.out("lens_overlay.png"));
        let rest = ["--model", "equidistant", "--fov", "235", "-o", &json];
        self.with_bracket(
            &["lens", "detect"],
            &[&rest[..], &["--overlay", &overlay]].concat(),
        )?;
        crate::geometry::read_lens(&self.dir.join("lens.json"))
    }

    /// Step 2: calibrate the camera response once, sampling inside the circle. 600 samples: the
    /// bundled sky has few dark pixels (only the ground ring), and with the default 128 the toe
    /// of the curve below code ≈ 90 changes from seed to seed (RMS spread 0.25 ln units over 5
    /// seeds; 0.035 with 600, below the 0.05 threshold).
    fn calibrate(&self, lens: &LensProfile) -> Result<String> {
        let c = lens.circle;
        let circle = format!("{:.3},{:.3},{:.3}", c.cx, c.cy, c.r);
        let (camera, plot) = (self.out("camera.json"), self.out("response.png"));
        let rest = ["--circle", &circle, "--samples", "600", "--repeat", "5"];
        self.with_bracket(
            &["calibrate"],
            &[&rest[..], &["-o", &camera, "--plot", &plot]].concat(),
        )?;
        Ok(camera)
    }

    /// Step 3: merge with the profile, crop to the 180° dome, find the sun, mark north, make maps.
    fn merge(&self, camera: &str) -> Result<()> {
        let lens = self.out("lens.json");
        let geometry = ["--lens", &lens, "--crop", "--north", "0", "--sun", "auto"];
        let (sky, exr, latlong) = (
            self.out("sky.hdr"),
            self.out("sky.exr"),
            self.out("sky_latlong.hdr"),
        );
        let (preview, overlay) = (self.out("preview.jpg"), self.out("overlay.png"));
        let outputs = [
            "-o",
            &sky,
            "--exr",
            &exr,
            "--preview",
            &preview,
            "--overlay",
            &overlay,
            "--equirect",
            &latlong,
        ];
        self.with_bracket(
            &["merge"],
            &[&["--profile", camera][..], &geometry, &outputs].concat(),
        )
    }

    /// Step 4: accuracy against the ground truth the bracket was rendered from (uncropped merge),
    /// inside the 180° horizon, after one scale per channel (a response is known up to one
    /// constant per channel, so a bracket alone fixes white balance only up to that constant).
    fn compare(&self, camera: &str, lens: &LensProfile) -> Result<()> {
        let full = self.out("full.hdr");
        self.with_bracket(&["merge"], &["--profile", camera, "-o", &full])?;
        let c = lens.circle;
        let horizon = lens.radius_at_deg(90.0).context("lens")?;
        let dome = format!("{:.3},{:.3},{:.3}", c.cx, c.cy, horizon);
        let truth = self.input("truth.hdr");
        self.step(&["compare", &full, &truth, "--per-channel", "--circle", &dome])
    }

    /// Step 5: pictures.
    fn pictures(&self) -> Result<()> {
        let (sky, latlong) = (self.out("sky.hdr"), self.out("sky_latlong.hdr"));
        let minmax = self.out("tonemap_minmax.png");
        self.step(&["tonemap", &sky, "-o", &minmax, "--op", "minmax"])?;
        self.step(&["falsecolor", &sky, "-o", &self.out("falsecolor.png")])?;
        self.step(&["histogram", &sky, "-o", &self.out("histogram.png")])?;
        self.step(&["render", &latlong, "-o", &self.out("spheres.png")])?;
        self.step(&["info", &sky])
    }
}
