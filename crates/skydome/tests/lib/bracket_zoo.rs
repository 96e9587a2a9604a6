//! The bracket zoo: brackets as the world sends them, each generated here, encoded as a camera
//! or scanner would write it (JPEG, PNG, TIFF; 8 or 16 bits; grey, alpha, CMYK; EXIF), run
//! through [`pipeline::run`] with default options, and held to its verdict:
//!
//! - **merged** — every frame kept, and every frame agrees with the merge where it is well
//!   exposed (median |log2(E_frame / E_merged)| below a bound);
//! - **warned** — merged, with a warning that says what and names the file;
//! - **refused** — an error that gives the reason and names every file concerned.
//!
//! `docs/inputs.md` is the same table for users. Every row is checked, and all mismatches are
//! reported together.

use crate::encode::{self, Exif, Layout};
use skydome::bracket::{bin16, Frame, Pixels};
use skydome::pipeline::{self, EncodedFrame, Frames, Input, Options};
use skydome::response::Response;
use skydome::synth::{self, FilmScanOptions, SynthOptions};

/// Pixels of the zoo's scene photographs.
const W: usize = 96;
const H: usize = 64;

/// What a bracket must give.
#[derive(Debug, Clone, Copy)]
enum Verdict {
    /// Merged with this many frames and no warning.
    Merged(usize),
    /// Merged with this many frames and a warning containing every one of these texts.
    Warned(usize, &'static [&'static str]),
    /// Refused with a message containing every one of these texts.
    Refused(&'static [&'static str]),
}

/// One encoded file of a bracket.
struct File {
    name: String,
    bytes: Vec<u8>,
}

/// A zoo bracket: files in the order the user gives them, `--times` if any, the options.
struct Case {
    name: &'static str,
    files: Vec<File>,
    times: Option<Vec<f64>>,
    options: Options,
    verdict: Verdict,
    /// Largest accepted frame-to-merge disagreement, stops (see [`check`]).
    bound: f64,
}

/// The zoo's scene (a sky with clouds, not a fish-eye; the sun dimmed to 3, as behind thin
/// cloud, so that the shortest of EV −2, 0, +2 clips nothing) photographed at `evs` stops around
/// 1/250 s with the default simulated camera, 8-bit, no JPEG yet. Frames shortest first.
fn shots(evs: &[f64], seed: u64) -> Vec<Frame> {
    let mut truth = synth::scene(W, H, seed, None);
    truth.data.iter_mut().for_each(|v| *v = v.min(3.0));
    photo(&truth, evs, seed)
}

/// `truth` photographed at `evs` stops around 1/250 s by the default simulated camera.
fn photo(truth: &skydome::HdrImage, evs: &[f64], seed: u64) -> Vec<Frame> {
    synth::photograph(
        truth,
        &SynthOptions {
            evs: evs.to_vec(),
            seed,
            jpeg_quality: None,
            ..SynthOptions::default()
        },
    )
    .expect("synthetic bracket")
}

/// The scene with its sun (radiance 2¹¹, clipped at every exposure here).
fn sunny(evs: &[f64], seed: u64) -> Vec<Frame> {
    photo(&synth::scene(W, H, seed, None), evs, seed)
}

fn rgb(f: &Frame) -> &[u8] {
    match &f.pixels {
        Pixels::U8(v) => v,
        Pixels::U16(_) => unreachable!("the zoo's shots are 8-bit"),
    }
}

fn exif_time(t: f64) -> Exif {
    Exif {
        time_s: Some(t),
        ..Exif::default()
    }
}

/// Frames as JPEGs (quality 95) with their exposure time in EXIF, named `IMG_000k.jpg`.
fn jpegs(frames: &[Frame]) -> Vec<File> {
    frames
        .iter()
        .enumerate()
        .map(|(k, f)| File {
            name: format!("IMG_{k:04}.jpg"),
            bytes: encode::jpeg(
                rgb(f),
                f.width,
                f.height,
                95,
                Some(&exif_time(f.exposure.time_s)),
            ),
        })
        .collect()
}

/// Frames as PNGs in `layout` with their exposure time in an `eXIf` chunk.
fn pngs(frames: &[Frame], layout: Layout) -> Vec<File> {
    frames
        .iter()
        .enumerate()
        .map(|(k, f)| File {
            name: format!("frame_{k}.png"),
            bytes: encode::png(
                rgb(f),
                f.width,
                f.height,
                layout,
                Some(&exif_time(f.exposure.time_s)),
            ),
        })
        .collect()
}

fn times(frames: &[Frame]) -> Option<Vec<f64>> {
    Some(frames.iter().map(|f| f.exposure.time_s).collect())
}

/// A frame of one flat code.
fn flat(code: u8) -> Vec<u8> {
    vec![code; 3 * W * H]
}

/// The night sky: black (codes 0–2 of read noise), a moon disc (0.5 % of the pixels, radiance
/// 2⁸ above the brightest star) and stars; three frames 2 stops apart, the moon clipped in the
/// longest.
fn night(evs: &[f64]) -> Vec<Frame> {
    let mut truth = skydome::HdrImage {
        width: W,
        height: H,
        data: vec![0.0; 3 * W * H],
    };
    let (mx, my, r) = (30.0, 20.0, 3.9f64);
    for y in 0..H {
        for x in 0..W {
            let d = ((x as f64 + 0.5 - mx).powi(2) + (y as f64 + 0.5 - my).powi(2)).sqrt();
            let star = (x * 7919 + y * 104_729) % 97 == 0;
            let l = if d < r {
                2.0 * (1.0 - 0.3 * d / r)
            } else if star {
                0.02
            } else {
                1e-5
            };
            truth.data[3 * (y * W + x)..3 * (y * W + x) + 3].copy_from_slice(&[l as f32; 3]);
        }
    }
    synth::photograph(
        &truth,
        &SynthOptions {
            evs: evs.to_vec(),
            jpeg_quality: None,
            read_noise: 40.0,
            ..SynthOptions::default()
        },
    )
    .expect("night frames")
}

fn cases() -> Vec<Case> {
    let d = Options::default();
    let base = shots(&[-2.0, 0.0, 2.0], 1);
    let mut v = Vec::new();
    let mut case = |name, files, times, options: &Options, verdict| {
        v.push(Case {
            name,
            files,
            times,
            options: options.clone(),
            verdict,
            bound: match name {
                // Measured: the night's response rests on the moon and a few stars (0.35 stop),
                // the film scan's shortest frame holds only its windows (0.47 stop).
                n if n.starts_with("night") => 0.5,
                n if n.starts_with("film") => 0.6,
                _ => 0.25,
            },
        })
    };

    // Accepted as they are.
    case(
        "phone bracket, JPEG, EXIF times",
        jpegs(&base),
        None,
        &d,
        Verdict::Merged(3),
    );
    let two = shots(&[-1.0, 1.0], 2);
    case("2 frames", jpegs(&two), None, &d, Verdict::Merged(2));
    let sixteen: Vec<f64> = (0..16).map(|k| k as f64 - 10.0).collect();
    case(
        "16 frames 1 stop apart",
        pngs(&shots(&sixteen, 3), Layout::Rgb8),
        None,
        &d,
        Verdict::Merged(16),
    );
    let thirds: Vec<f64> = (0..7).map(|k| (k as f64 - 3.0) / 3.0).collect();
    case(
        "⅓-stop steps",
        jpegs(&shots(&thirds, 4)),
        None,
        &d,
        Verdict::Merged(7),
    );
    let mut unsorted = jpegs(&base);
    unsorted.swap(0, 2);
    unsorted.swap(1, 2);
    case("unsorted input", unsorted, None, &d, Verdict::Merged(3));
    case(
        "16-bit PNG",
        pngs(&base, Layout::Rgb16),
        None,
        &d,
        Verdict::Merged(3),
    );
    let tiffs: Vec<File> = base
        .iter()
        .enumerate()
        .map(|(k, f)| File {
            name: format!("scan_{k}.tif"),
            bytes: encode::tiff(rgb(f), W, H, Layout::Rgb16),
        })
        .collect();
    case(
        "16-bit TIFF, times given",
        tiffs,
        times(&base),
        &d,
        Verdict::Merged(3),
    );
    case(
        "grey (1-channel) PNG",
        pngs(&base, Layout::Grey8),
        None,
        &d,
        Verdict::Merged(3),
    );
    case(
        "alpha channel (RGBA PNG)",
        pngs(&base, Layout::Rgba8),
        None,
        &d,
        Verdict::Merged(3),
    );
    let cmyk: Vec<File> = base
        .iter()
        .enumerate()
        .map(|(k, f)| File {
            name: format!("print_{k}.jpg"),
            bytes: encode::jpeg_cmyk(rgb(f), W, H, Some(&exif_time(f.exposure.time_s))),
        })
        .collect();
    case("CMYK JPEG", cmyk, None, &d, Verdict::Merged(3));
    let rotated: Vec<File> = base
        .iter()
        .enumerate()
        .map(|(k, f)| File {
            name: format!("IMG_{k:04}.jpg"),
            bytes: encode::jpeg(
                rgb(f),
                W,
                H,
                95,
                Some(&Exif {
                    orientation: Some(6),
                    ..exif_time(f.exposure.time_s)
                }),
            ),
        })
        .collect();
    case(
        "every frame rotated by EXIF (6)",
        rotated,
        None,
        &d,
        Verdict::Merged(3),
    );
    case(
        "night sky with a moon",
        pngs(&night(&[-2.0, 0.0, 2.0]), Layout::Rgb8),
        None,
        &d,
        Verdict::Warned(3, &["black in every frame"]),
    );
    // The sun and most of the sky clipped in the two longest frames.
    let sun = sunny(&[-2.0, 0.0, 2.0, 4.0, 6.0], 5);
    case(
        "the sun; the long frames mostly clipped",
        jpegs(&sun),
        None,
        &d,
        Verdict::Warned(5, &["clipped even in the shortest exposure"]),
    );
    let film = synth::film_scan(&FilmScanOptions {
        width: 128,
        height: 192,
        seed: 7,
    })
    .expect("film scan");
    let film_files: Vec<File> = film
        .frames
        .iter()
        .map(|f| File {
            name: f.name.clone(),
            bytes: f.png.clone(),
        })
        .collect();
    let film_times = Some(film.frames.iter().map(|f| f.time_s).collect());
    case(
        "film-scan pedestal (16 × 1 EV)",
        film_files,
        film_times,
        &d,
        Verdict::Merged(16),
    );
    let film_bl = Options {
        black_level: 18,
        ..d.clone()
    };
    let film_files: Vec<File> = film
        .frames
        .iter()
        .map(|f| File {
            name: f.name.clone(),
            bytes: f.png.clone(),
        })
        .collect();
    let film_times = Some(film.frames.iter().map(|f| f.time_s).collect());
    case(
        "film-scan pedestal, --black-level 18",
        film_files,
        film_times,
        &film_bl,
        Verdict::Merged(16),
    );

    // Merged with a warning.
    // One shutter time, ISO 100/400/1600: relative exposures t·ISO/100 two stops apart.
    let iso: Vec<File> = base
        .iter()
        .zip([100u16, 400, 1600])
        .enumerate()
        .map(|(k, (f, s))| File {
            name: format!("IMG_{k:04}.jpg"),
            bytes: encode::jpeg(
                rgb(f),
                W,
                H,
                95,
                Some(&Exif {
                    iso: Some(s),
                    ..exif_time(1.0 / 250.0)
                }),
            ),
        })
        .collect();
    case(
        "ISO bracket (one time, ISO 100/400/1600)",
        iso,
        None,
        &d,
        Verdict::Warned(3, &["ISO differs", "IMG_0000.jpg", "IMG_0001.jpg"]),
    );
    let mut black = jpegs(&base);
    black.push(File {
        name: "IMG_black.jpg".into(),
        bytes: encode::jpeg(&flat(0), W, H, 95, Some(&exif_time(1.0 / 8000.0))),
    });
    case(
        "a flat black frame",
        black,
        None,
        &d,
        Verdict::Warned(3, &["IMG_black.jpg", "left out"]),
    );
    let mut white = jpegs(&base);
    white.push(File {
        name: "IMG_white.jpg".into(),
        bytes: encode::jpeg(&flat(255), W, H, 95, Some(&exif_time(1.0))),
    });
    case(
        "a flat white frame",
        white,
        None,
        &d,
        Verdict::Warned(3, &["IMG_white.jpg", "left out"]),
    );

    // Refused.
    let mut dup = jpegs(&base);
    dup[2].bytes = encode::jpeg(
        rgb(&base[2]),
        W,
        H,
        95,
        Some(&exif_time(base[1].exposure.time_s)),
    );
    case(
        "duplicate time",
        dup,
        None,
        &d,
        Verdict::Refused(&["IMG_0001.jpg", "IMG_0002.jpg", "within 1/6 stop"]),
    );
    let mut swapped = jpegs(&base);
    swapped[0].bytes = encode::jpeg(
        rgb(&base[0]),
        W,
        H,
        95,
        Some(&exif_time(base[1].exposure.time_s)),
    );
    swapped[1].bytes = encode::jpeg(
        rgb(&base[1]),
        W,
        H,
        95,
        Some(&exif_time(base[0].exposure.time_s)),
    );
    case(
        "swapped times",
        swapped,
        None,
        &d,
        Verdict::Refused(&[
            "IMG_0000.jpg",
            "IMG_0001.jpg",
            "exposure times do not belong",
        ]),
    );
    // Like ../shared/data/ssarcandy_street: four shots at one exposure (each with its own
    // noise) although EXIF says 1/250 … 1/30 s.
    let mut ignored = jpegs(&shots(&[-2.0, 0.0, 0.001, 0.002, 0.003, 2.0], 6));
    let said = [
        1.0 / 1000.0,
        1.0 / 250.0,
        1.0 / 125.0,
        1.0 / 60.0,
        1.0 / 30.0,
        1.0 / 8.0,
    ];
    for (f, (file, t)) in shots(&[-2.0, 0.0, 0.001, 0.002, 0.003, 2.0], 6)
        .iter()
        .zip(ignored.iter_mut().zip(said))
    {
        file.bytes = encode::jpeg(rgb(f), W, H, 95, Some(&exif_time(t)));
    }
    case(
        "camera ignored the bracket (4 frames, one exposure)",
        ignored,
        None,
        &d,
        Verdict::Refused(&[
            "IMG_0001.jpg",
            "IMG_0002.jpg",
            "IMG_0003.jpg",
            "IMG_0004.jpg",
            "nearly identical",
        ]),
    );
    // Chromium's fake camera (the phone app's browser tests) ignores the exposure asked for:
    // flat green (0, 127, 0) with a 40-pixel yellow square in each corner whose level steps on
    // between shots. Identical where it matters, though the corners reorder the only blocks
    // that differ (the levels of three of its shots, read from takePhoto()).
    let (fw, fh) = (640, 480);
    let fake = |corners: [u8; 4], k: usize| {
        let px: Vec<u8> = (0..fw * fh)
            .flat_map(|p| {
                let (x, y) = (p % fw, p / fw);
                let corner = match (x < 40, x >= fw - 40, y < 40, y >= fh - 40) {
                    (true, _, true, _) => Some(corners[0]),
                    (_, true, true, _) => Some(corners[1]),
                    (true, _, _, true) => Some(corners[2]),
                    (_, true, _, true) => Some(corners[3]),
                    _ => None,
                };
                corner.map_or([0, 127, 0], |v| [v, v, 0])
            })
            .collect();
        File {
            name: format!("shot_{k}.png"),
            bytes: encode::png(
                &px,
                fw,
                fh,
                Layout::Rgb8,
                Some(&exif_time(0.004 * 2f64.powi(k as i32))),
            ),
        }
    };
    case(
        "camera ignored the bracket, something changed between shots",
        vec![
            fake([61, 204, 167, 54], 0),
            fake([153, 40, 3, 146], 1),
            fake([7, 150, 113, 0], 2),
        ],
        None,
        &d,
        Verdict::Refused(&["shot_0.png", "shot_1.png", "shot_2.png", "nearly identical"]),
    );
    // The middle frame from another view (the camera panned half a frame and tilted, its
    // ground and sky where the bracket has others), at the middle frame's exposure.
    let mut turned = shots(&[0.0], 9).remove(0);
    let px = (0..W * H)
        .flat_map(|p| {
            let (x, y) = ((p % W + W / 2) % W, (p / W + H / 2) % H);
            rgb(&turned)[3 * (y * W + x)..3 * (y * W + x) + 3].to_vec()
        })
        .collect();
    turned.pixels = Pixels::U8(px);
    let mut foreign = jpegs(&base);
    foreign[1].bytes = encode::jpeg(
        rgb(&turned),
        W,
        H,
        95,
        Some(&exif_time(base[1].exposure.time_s)),
    );
    case(
        "one frame from another scene",
        foreign,
        None,
        &d,
        // Too little of the shortest frame is picture where the stray one is to compare them;
        // the stray frame and its other neighbour are named together.
        Verdict::Refused(&[
            "IMG_0001.jpg and IMG_0002.jpg do not show one scene",
            "leave out the one that does not belong",
        ]),
    );
    // The same at an end of the exposure order: its neighbour matches the frame beyond.
    let mut foreign_end = jpegs(&base);
    foreign_end[2].bytes = encode::jpeg(
        rgb(&turned),
        W,
        H,
        95,
        Some(&exif_time(base[2].exposure.time_s)),
    );
    case(
        "the longest frame from another scene",
        foreign_end,
        None,
        &d,
        Verdict::Refused(&["IMG_0002.jpg does not show the scene of IMG_0001.jpg"]),
    );
    let mut size = jpegs(&base);
    let small = shots(&[2.0], 1);
    let cropped: Vec<u8> = rgb(&small[0])[..3 * W * (H - 8)].to_vec();
    size[2].bytes = encode::jpeg(
        &cropped,
        W,
        H - 8,
        95,
        Some(&exif_time(base[2].exposure.time_s)),
    );
    case(
        "one frame a different size",
        size,
        None,
        &d,
        Verdict::Refused(&["IMG_0002.jpg", "96x56", "96x64"]),
    );
    let mut one_rotated = jpegs(&base);
    one_rotated[1].bytes = encode::jpeg(
        rgb(&base[1]),
        W,
        H,
        95,
        Some(&Exif {
            orientation: Some(6),
            ..exif_time(base[1].exposure.time_s)
        }),
    );
    case(
        "one frame rotated by EXIF",
        one_rotated,
        None,
        &d,
        Verdict::Refused(&["IMG_0001.jpg", "orientation 6", "ignore EXIF orientation"]),
    );
    let mut depths = pngs(&base, Layout::Rgb8);
    depths[1].bytes = encode::png(
        rgb(&base[1]),
        W,
        H,
        Layout::Rgb16,
        Some(&exif_time(base[1].exposure.time_s)),
    );
    case(
        "mixed bit depths",
        depths,
        None,
        &d,
        Verdict::Refused(&["frame_1.png", "16-bit", "8-bit"]),
    );
    let lone = vec![
        jpegs(&base).remove(1),
        File {
            name: "IMG_black.jpg".into(),
            bytes: encode::jpeg(&flat(0), W, H, 95, Some(&exif_time(1.0 / 8000.0))),
        },
    ];
    case(
        "2 frames, one flat black",
        lone,
        None,
        &d,
        Verdict::Refused(&["IMG_black.jpg", "2 frames", "left out"]),
    );
    let no_exif: Vec<File> = base
        .iter()
        .enumerate()
        .map(|(k, f)| File {
            name: format!("frame_{k}.png"),
            bytes: encode::png(rgb(f), W, H, Layout::Rgb8, None),
        })
        .collect();
    case(
        "no exposure times anywhere",
        no_exif,
        None,
        &d,
        Verdict::Refused(&[
            "frame_0.png",
            "frame_1.png",
            "frame_2.png",
            "no exposure time",
        ]),
    );
    let mut cut = jpegs(&base);
    let n = cut[1].bytes.len();
    cut[1].bytes.truncate(n * 2 / 3);
    case(
        "a truncated JPEG",
        cut,
        None,
        &d,
        Verdict::Refused(&["IMG_0001.jpg", "truncated"]),
    );
    v
}

/// Per frame, the median over its well-exposed pixels (all channels in 40..=235 of 255: clear
/// of a film scan's pedestal and its noise, and of clipping) of |log2(E_frame / E_merged)|,
/// `E_frame = exp(g(Z)) / relative exposure`.
pub fn consistency(frames: &[Frame], r: &Response, merged: &skydome::HdrImage) -> Vec<f64> {
    frames
        .iter()
        .map(|f| {
            let code = |i: usize| -> u8 {
                match &f.pixels {
                    Pixels::U8(v) => v[i],
                    Pixels::U16(v) => bin16(v[i]),
                }
            };
            let lt = f.exposure.relative().ln();
            let mut d = Vec::new();
            for p in 0..f.width * f.height {
                let z = [code(3 * p), code(3 * p + 1), code(3 * p + 2)];
                if z.iter().all(|z| (40..=235).contains(z)) {
                    for (c, &zc) in z.iter().enumerate() {
                        let m = f64::from(merged.data[3 * p + c]).max(1e-30).ln();
                        d.push(((r.curve(c)[zc as usize] - lt - m) / std::f64::consts::LN_2).abs());
                    }
                }
            }
            if d.is_empty() {
                return 0.0;
            }
            d.sort_by(f64::total_cmp);
            d[d.len() / 2]
        })
        .collect()
}

/// Checks one case; `Err` says how it missed its verdict.
fn check(c: Case) -> Result<String, String> {
    let input = || Input {
        times: c.times.clone(),
        ..Input::new(Frames::Encoded(
            c.files
                .iter()
                .map(|f| EncodedFrame {
                    name: f.name.clone(),
                    bytes: f.bytes.clone(),
                })
                .collect(),
        ))
    };
    let result = pipeline::run(input(), &c.options, &mut pipeline::no_progress);
    let (frames, warnings_expected) = match (c.verdict, result) {
        (Verdict::Refused(texts), Err(e)) => {
            let msg = e.to_string();
            return match texts.iter().find(|t| !msg.contains(*t)) {
                None => Ok(format!("refused: {msg}")),
                Some(t) => Err(format!("refused, but the message lacks '{t}': {msg}")),
            };
        }
        (Verdict::Refused(_), Ok(_)) => return Err("merged, expected a refusal".into()),
        (_, Err(e)) => return Err(format!("refused: {e}")),
        (Verdict::Merged(n), Ok(dome)) => (n, (dome, None)),
        (Verdict::Warned(n, texts), Ok(dome)) => (n, (dome, Some(texts))),
    };
    let (dome, texts) = warnings_expected;
    if dome.report.frames.len() != frames {
        return Err(format!(
            "merged {} frames, expected {frames}",
            dome.report.frames.len()
        ));
    }
    match texts {
        None if !dome.report.warnings.is_empty() => {
            return Err(format!("unexpected warnings: {:?}", dome.report.warnings))
        }
        Some(texts)
            if !dome
                .report
                .warnings
                .iter()
                .any(|w| texts.iter().all(|t| w.contains(t))) =>
        {
            return Err(format!(
                "no warning with {texts:?}: {:?}",
                dome.report.warnings
            ))
        }
        _ => {}
    }
    let br =
        pipeline::load_bracket(input(), &mut pipeline::no_progress).map_err(|e| e.to_string())?;
    let response = match &dome.camera_profile {
        Some(p) => p.response().map_err(|e| e.to_string())?,
        None => return Err("no calibration".into()),
    };
    let worst = consistency(&br.frames, &response, &dome.radiance)
        .into_iter()
        .fold(0.0, f64::max);
    // A frame that agrees with the merge to within 0.25 stops (median over its well-exposed
    // pixels; looser for the night and the film scan, see `cases`); a wrong time or a broken
    // decode is off by a stop or more.
    if worst > c.bound {
        return Err(format!(
            "a frame disagrees with the merge by {worst:.3} stops"
        ));
    }
    Ok(format!(
        "{} frames, worst frame {worst:.3} stops; warnings {:?}",
        frames, dome.report.warnings
    ))
}

#[test]
fn every_bracket_in_the_zoo_gets_its_verdict() {
    let cases = cases();
    assert!(cases.len() >= 20);
    let mut failed = Vec::new();
    for c in cases {
        let name = c.name;
        match check(c) {
            Ok(s) => println!("ok   {name}: {s}"),
            Err(s) => {
                println!("FAIL {name}: {s}");
                failed.push(format!("{name}: {s}"));
            }
        }
    }
    assert!(
        failed.is_empty(),
        "{} cases missed their verdict:\n{}",
        failed.len(),
        failed.join("\n")
    );
}
