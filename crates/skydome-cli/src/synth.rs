//! `skydome synth -o DIR`: a synthetic fish-eye bracket with known answers (ground truth for
//! accuracy checks and the OpenCV comparison script).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use skydome::bracket::Pixels;
use skydome::formats::HdrMeta;
use skydome::image::RgbImage;
use skydome::synth::{self, SynthOptions};

use crate::io::{self, Outputs};

/// Arguments of `skydome synth`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Folder to write into (must exist).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Image side in pixels.
    #[arg(long, default_value_t = 512)]
    pub size: usize,
    /// Exposure values of the frames, relative to the base time.
    #[arg(long, default_value = "-2,0,2", allow_hyphen_values = true)]
    pub evs: String,
    /// Seed of the scene and the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// JPEG quality of the frames (0 writes lossless PNG instead).
    #[arg(long, default_value_t = 92)]
    pub quality: u8,
    /// A station's day instead of one bracket: this many captures (seeds `seed`, `seed+1`, …)
    /// written into one folder as IMG_0000.jpg, IMG_0001.jpg, … with EXIF exposure time, capture
    /// time (frames 1 s apart) and UTC offset, for `skydome batch`.
    #[arg(long, value_name = "N")]
    pub captures: Option<usize>,
    /// Time of the first capture (ISO 8601 with offset), with --captures.
    #[arg(
        long,
        value_name = "ISO8601",
        default_value = "2026-06-21T06:00:00+02:00"
    )]
    pub start: String,
    /// Seconds between captures, with --captures.
    #[arg(long, value_name = "SECONDS", default_value_t = 3600)]
    pub interval: u32,
    /// Latitude,longitude written as EXIF GPS, with --captures.
    #[arg(long, value_name = "LAT,LON", allow_hyphen_values = true)]
    pub gps: Option<String>,
    /// ISO speed written as EXIF, with --captures (a camera whose frames carry it).
    #[arg(long, value_name = "ISO")]
    pub iso: Option<f64>,
    /// Aperture f-number written as EXIF, with --captures.
    #[arg(long, value_name = "N")]
    pub f_number: Option<f64>,
    /// Replace existing files.
    #[arg(long)]
    pub force: bool,
}

/// The top-level entry point for `skydome synth`.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    if !a.output.is_dir() {
        bail!("{}: not a folder (create it first)", a.output.display());
    }
    let evs = a
        .evs
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<Vec<_>, _>>()
        .with_context(|| format!("--evs '{}': expected numbers such as -2,0,2", a.evs))?;
    let opts = SynthOptions {
        width: a.size,
        height: a.size,
        evs,
        seed: a.seed,
        jpeg_quality: (a.quality > 0).then_some(a.quality),
        ..SynthOptions::default()
    };
    if let Some(n) = a.captures {
        return day(&a, &opts, n, quiet);
    }
    let spin = io::spinner(quiet, "rendering");
    let b = synth::generate(&opts).context("synthetic bracket")?;
    spin.finish_and_clear();
    let ext = if a.quality > 0 { "jpg" } else { "png" };
    let mut out = Outputs::default();
    let mut list = String::from("# FILE TIME(s) — synthetic bracket written by skydome synth\n");
    for (i, f) in b.frames.iter().enumerate() {
        let name = format!("frame_{i}.{ext}");
        let Pixels::U8(data) = &f.pixels else {
            bail!("synthetic frames are 8-bit");
        };
        let img = RgbImage::from_vec(f.width, f.height, data.clone()).context("frame size")?;
        let p = a.output.join(&name);
        let bytes = match ext {
            // Frames already carry their JPEG artefacts; store them losslessly at high quality.
            "jpg" => encode_jpeg(&img, 98)?,
            _ => crate::pictures::encode_rgb8(&p, &img)?,
        };
        out.add(&p, bytes);
        list += &format!("{name} {}\n", f.exposure.time_s);
    }
    out.add(&a.output.join("times.txt"), list.into_bytes());
    let truth = a.output.join("truth.hdr");
    out.add(
        &truth,
        crate::radiance::encode(&truth, &b.truth, &HdrMeta::default(), &Default::default())?,
    );
    let mut csv = String::from("z,g_red,g_green,g_blue\n");
    for z in 0..256 {
        csv += &format!(
            "{z},{},{},{}\n",
            b.true_g[0][z], b.true_g[1][z], b.true_g[2][z]
        );
    }
    out.add(&a.output.join("true_curves.csv"), csv.into_bytes());
    if let Some(c) = b.circle {
        out.add(
            &a.output.join("circle.txt"),
            format!("{},{},{}\n", c.cx, c.cy, c.r).into_bytes(),
        );
    }
    for p in out.commit(&[], a.force)? {
        if !quiet {
            crate::out(&format!("wrote {}", p.display()));
        }
    }
    Ok(())
}

/// `--captures N`: a station's day of JPEGs with EXIF in one folder.
fn day(a: &Args, opts: &SynthOptions, n: usize, quiet: bool) -> Result<()> {
    use skydome::formats::exif::{insert_into_jpeg, ExifFields};
    if a.quality == 0 {
        bail!("--captures writes JPEGs (EXIF); give a --quality above 0");
    }
    let start = skydome::bracket::parse_iso8601(&a.start).with_context(|| {
        format!(
            "--start '{}': expected ISO 8601 with a UTC offset, e.g. 2026-06-21T06:00:00+02:00",
            a.start
        )
    })?;
    let gps = match &a.gps {
        Some(g) => {
            let v: Vec<f64> = g
                .split(',')
                .map(|t| t.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .with_context(|| format!("--gps '{g}': expected LAT,LON in degrees"))?;
            match v[..] {
                [lat, lon] => Some((lat, lon)),
                _ => bail!("--gps '{g}': expected LAT,LON in degrees"),
            }
        }
        None => None,
    };
    let (h, m, _) = start.offset().as_hms();
    let offset = format!(
        "{}{:02}:{:02}",
        if start.offset().is_negative() {
            '-'
        } else {
            '+'
        },
        h.unsigned_abs(),
        m.unsigned_abs()
    );
    let bar = io::progress(quiet, n as u64, "rendering");
    let mut out = Outputs::default();
    let mut k = 0;
    for c in 0..n {
        let b = synth::generate(&SynthOptions {
            seed: opts.seed + c as u64,
            ..opts.clone()
        })
        .context("synthetic bracket")?;
        for (i, f) in b.frames.iter().enumerate() {
            let Pixels::U8(data) = &f.pixels else {
                bail!("synthetic frames are 8-bit");
            };
            let img = RgbImage::from_vec(f.width, f.height, data.clone()).context("frame size")?;
            let t = start + time::Duration::seconds(i64::from(a.interval) * c as i64 + i as i64);
            let fields = ExifFields {
                exposure_time_s: Some(f.exposure.time_s),
                datetime_original: Some(skydome::bracket::format_exif_datetime(
                    time::PrimitiveDateTime::new(t.date(), t.time()),
                )),
                subsec_original: None,
                offset_time_original: Some(offset.clone()),
                gps_deg: gps,
                iso: a.iso,
                f_number: a.f_number,
            };
            let jpeg = insert_into_jpeg(&encode_jpeg(&img, 98)?, &fields).context("EXIF")?;
            out.add(&a.output.join(format!("IMG_{k:04}.jpg")), jpeg);
            k += 1;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let written = out.commit(&[], a.force)?;
    if !quiet {
        crate::out(&format!(
            "wrote {} frames of {n} captures into {}",
            written.len(),
            a.output.display()
        ));
    }
    Ok(())
}

fn encode_jpeg(img: &RgbImage<u8>, q: u8) -> Result<Vec<u8>> {
    let mut v = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut v, q),
        &img.data,
        img.width as u32,
        img.height as u32,
        image::ExtendedColorType::Rgb8,
    )
    .context("JPEG encoding")?;
    Ok(v)
}
