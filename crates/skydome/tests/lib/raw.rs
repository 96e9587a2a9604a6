//! RAW (DNG) brackets: the real sample decodes, synthetic RAW brackets merge to within the
//! oracle's error, malformed files give one-line errors, and the standard error the merge
//! states matches the error it makes.

use skydome::bracket::{self, DecodeOptions, Pixels};
use skydome::image::HdrImage;
use skydome::merge::{self, LinearNoise};
use skydome::pipeline::{self, EncodedFrame, Frames, Input, LensSource, Options};
use skydome::synth::{self, RawSynthOptions};

use crate::common::required::shared_data;

/// The scene of the synthetic fish-eye bracket (sky, clouds, a clipped sun, dim ground),
/// `size` pixels square, as camera RGB.
fn scene(size: usize, seed: u64) -> HdrImage {
    let c = skydome::image::Circle {
        cx: size as f64 / 2.0,
        cy: size as f64 / 2.0,
        r: 0.48 * size as f64,
    };
    synth::scene(size, size, seed, Some(c))
}

fn encoded(files: Vec<(String, Vec<u8>)>) -> Vec<EncodedFrame> {
    files
        .into_iter()
        .map(|(name, bytes)| EncodedFrame { name, bytes })
        .collect()
}

fn no_lens() -> Options {
    Options {
        lens: LensSource::None,
        ..Options::default()
    }
}

#[test]
fn tinydng_sample_decodes_with_its_cfa_and_levels() {
    let Some(dir) = shared_data("raw_dng") else {
        return;
    };
    let bytes = std::fs::read(dir.join("tinydng_colorchart.dng")).unwrap();
    assert!(bracket::is_dng(&bytes));
    let (f, colour) =
        bracket::decode_raw("colorchart.dng", &bytes, &DecodeOptions::default()).unwrap();
    let colour = colour.expect("a DNG has a colour");
    // The 1888 × 1182 sensor, cropped to its ActiveArea.
    assert_eq!((f.width, f.height), (1734, 1156));
    assert_eq!(colour.cfa, Some([0, 1, 1, 2]), "RGGB");
    assert!(colour.white_level > colour.black_level);
    // The exposure fields are empty in this file: a bracket of it needs given times.
    assert_eq!(f.exif_time_s, None);
    let Pixels::U16(px) = &f.pixels else {
        panic!("RAW frames are 16-bit")
    };
    // A colour chart: most values between black and white, a few clipped at most.
    let vals: Vec<f32> = px
        .iter()
        .filter_map(|&c| bracket::dng::raw_value(c))
        .collect();
    let clipped = px.len() - vals.len();
    assert!(
        clipped * 100 < px.len(),
        "{clipped} of {} clipped",
        px.len()
    );
    let mean = vals.iter().map(|&v| f64::from(v)).sum::<f64>() / vals.len() as f64;
    assert!((0.01..0.9).contains(&mean), "mean raw value {mean}");
    eprintln!(
        "tinydng: {}x{}, black {} white {}, matrix {}, mean raw value {mean:.3}",
        f.width, f.height, colour.black_level, colour.white_level, colour.matrix_from
    );
}

/// log2 errors per channel over the measured pixels of `got` against `truth`, where the truth
/// is smooth (each channel within 25 % over the 3 × 3 neighbourhood): at edges — the lens
/// circle, the sun, cloud borders — bilinear demosaicing, not the merge, makes the error.
fn log_errors(got: &HdrImage, truth: &HdrImage, sigma: &HdrImage) -> Vec<f64> {
    let w = truth.width;
    let mut e = Vec::new();
    for y in 1..truth.height - 1 {
        for x in 1..w - 1 {
            for c in 0..3 {
                let k = 3 * (y * w + x) + c;
                let (g, t, s) = (got.data[k], truth.data[k], sigma.data[k]);
                let (mut lo, mut hi) = (f32::INFINITY, 0f32);
                for yy in y - 1..=y + 1 {
                    for xx in x - 1..=x + 1 {
                        let v = truth.data[3 * (yy * w + xx) + c];
                        lo = lo.min(v);
                        hi = hi.max(v);
                    }
                }
                if t > 0.0 && g > 0.0 && s.is_finite() && lo > 0.0 && hi < 1.25 * lo {
                    e.push((f64::from(g) / f64::from(t)).log2());
                }
            }
        }
    }
    e
}

/// The truth in the merge's units: raw value per unit of relative exposure (`t · ISO/100 / N²`),
/// `v = L · t · k` with `k = 0.25 / base_time_s`.
fn in_merge_units(truth: &HdrImage, o: &RawSynthOptions) -> HdrImage {
    let s = 0.25 / o.base_time_s * o.f_number * o.f_number * 100.0 / f64::from(o.iso);
    HdrImage {
        width: truth.width,
        height: truth.height,
        data: truth
            .data
            .iter()
            .map(|&v| (f64::from(v) * s) as f32)
            .collect(),
    }
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// The merge with the noise estimated from the frames against the same merge with the
/// sensor's true noise (the oracle), on brackets from seeds the code was not tuned on.
#[test]
fn synthetic_raw_brackets_merge_within_the_oracle_targets() {
    for (evs, seed, target) in [
        (vec![-2.0, 0.0, 2.0], 11u64, 1.10),
        (vec![-3.0, 0.0, 3.0], 12, 1.10),
        (vec![-4.0, -2.0, 0.0, 2.0, 4.0], 13, 1.05),
    ] {
        let opts = RawSynthOptions {
            evs: evs.clone(),
            seed,
            ..RawSynthOptions::default()
        };
        let scene = scene(192, seed);
        let files = synth::raw_bracket(&scene, &opts).unwrap();
        let truth = in_merge_units(&scene, &opts);
        let dome = pipeline::run(
            Input::new(Frames::Encoded(encoded(files.clone()))),
            &Options {
                products: pipeline::Products {
                    confidence: true,
                    ..Default::default()
                },
                ..no_lens()
            },
            &mut pipeline::no_progress,
        )
        .unwrap();
        assert_eq!(dome.report.response, "linear (RAW)");
        let raw = dome.report.raw.as_ref().expect("RAW report");
        assert!(raw.noise.fitted);
        // The sensor's own noise, in units of the white level.
        let white = f64::from(opts.white - opts.black);
        let a = 1.0 / opts.full_well;
        let b = (opts.read_noise / opts.full_well).powi(2) + 1.0 / 12.0 / (white * white);
        for c in 0..3 {
            let (fa, fb) = (raw.noise.a[c], raw.noise.b[c]);
            assert!(
                (fa / a - 1.0).abs() < 0.25,
                "channel {c}: shot coefficient {fa:.3e}, true {a:.3e}"
            );
            assert!(
                (fb.sqrt() / b.sqrt() - 1.0).abs() < 0.5,
                "channel {c}: read noise {:.3e}, true {:.3e}",
                fb.sqrt(),
                b.sqrt()
            );
        }
        // The oracle: the same frames merged with the true noise.
        let br = pipeline::load_bracket(
            Input::new(Frames::Encoded(encoded(files))),
            &mut pipeline::no_progress,
        )
        .unwrap();
        let (_, colour) = bracket::decode_raw(
            "f",
            &synth::raw_bracket(&scene, &opts).unwrap()[0].1,
            &DecodeOptions::default(),
        )
        .unwrap();
        let colour = colour.unwrap();
        let oracle = merge::merge_linear(
            &br.frames,
            &colour,
            Some(LinearNoise {
                a: [a; 3],
                b: [b; 3],
                fitted: true,
                differences: 0,
            }),
        )
        .unwrap();
        let sigma = dome.standard_error.as_ref().unwrap();
        let ours = rms(&log_errors(&dome.radiance, &truth, sigma));
        let best = rms(&log_errors(&oracle.radiance, &truth, sigma));
        let ratio = ours / best;
        eprintln!(
            "RAW {} frames, EV step {}: log2 RMS error {ours:.4} stops, oracle {best:.4}, ratio {ratio:.3}; noise a {:.3e} (true {a:.3e}), √b {:.3e} (true {:.3e}); median σ {:.4} stops",
            evs.len(),
            evs[1] - evs[0],
            raw.noise.a[1],
            raw.noise.b[1].sqrt(),
            b.sqrt(),
            dome.report.standard_error.unwrap().median_stops,
        );
        assert!(ratio <= target, "ratio {ratio:.3} above {target}");
        assert!(ours < 0.1, "log2 RMS error {ours:.4} stops");
    }
}

/// The standard error the RAW merge states matches the error it makes: on a smooth scene
/// (no demosaicing error), |error| / σ has the median of a unit normal's absolute value, 0.674.
#[test]
fn raw_standard_error_matches_the_actual_error() {
    let size = 128;
    let mut truth = HdrImage::new(size, size);
    for y in 0..size {
        for x in 0..size {
            // 12 stops across, constant colour per row band: smooth for bilinear demosaicing.
            let l = (-8.0 + 12.0 * x as f64 / size as f64).exp2() as f32;
            truth.data[3 * (y * size + x)..3 * (y * size + x) + 3].copy_from_slice(&[
                l * 0.8,
                l,
                l * 0.6,
            ]);
        }
    }
    let opts = RawSynthOptions {
        seed: 21,
        ..RawSynthOptions::default()
    };
    let files = synth::raw_bracket(&truth, &opts).unwrap();
    let truth = in_merge_units(&truth, &opts);
    let (_, colour) = bracket::decode_raw("f", &files[0].1, &DecodeOptions::default()).unwrap();
    let br = pipeline::load_bracket(
        Input::new(Frames::Encoded(encoded(files))),
        &mut pipeline::no_progress,
    )
    .unwrap();
    let m = merge::merge_linear(&br.frames, &colour.unwrap(), None).unwrap();
    // Only measured (native) photosites: interpolated values share photosites with their
    // neighbours, and the gradient is exponential, so their error is not pure noise.
    let cfa = [0usize, 1, 1, 2];
    let mut z = Vec::new();
    for y in 1..size - 1 {
        for x in 1..size - 1 {
            let c = cfa[(y & 1) * 2 + (x & 1)];
            let k = 3 * (y * size + x) + c;
            let s = m.sigma_stops.data[k];
            if s.is_finite() && m.clipped[y * size + x] == 0 {
                let e = (f64::from(m.radiance.data[k]) / f64::from(truth.data[k])).log2();
                z.push(e.abs() / f64::from(s));
            }
        }
    }
    z.sort_by(f64::total_cmp);
    let med = z[z.len() / 2];
    let p90 = z[z.len() * 9 / 10];
    eprintln!(
        "RAW |error|/σ over {} photosites: median {med:.3} (normal 0.674), p90 {p90:.3} (normal 1.645)",
        z.len()
    );
    assert!((med - 0.674).abs() < 0.07, "median |error|/σ {med:.3}");
    assert!((p90 - 1.645).abs() < 0.2, "p90 |error|/σ {p90:.3}");
}

#[test]
fn raw_brackets_run_through_the_pipeline_with_exif_exposure() {
    let truth = scene(96, 5);
    let opts = RawSynthOptions::default();
    let files = synth::raw_bracket(&truth, &opts).unwrap();
    let dome = pipeline::run(
        Input::new(Frames::Encoded(encoded(files))),
        &no_lens(),
        &mut pipeline::no_progress,
    )
    .unwrap();
    let f = &dome.report.frames;
    assert_eq!(f.len(), 3);
    assert!((f[0].time_s - 1.0 / 1000.0).abs() < 1e-6, "{:?}", f[0]);
    assert_eq!(f[1].iso, Some(100.0));
    assert_eq!(f[1].f_number, Some(1.8));
    assert!(dome
        .radiance
        .data
        .iter()
        .all(|v| v.is_finite() && *v >= 0.0));
}

#[test]
fn a_bracket_mixing_raw_and_jpeg_is_refused() {
    let truth = scene(64, 3);
    let mut files = encoded(synth::raw_bracket(&truth, &RawSynthOptions::default()).unwrap());
    files[1] = EncodedFrame {
        name: "frame_1.jpg".into(),
        bytes: std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../demo/frame_1.jpg"
        ))
        .unwrap(),
    };
    let err = pipeline::run(
        Input::new(Frames::Encoded(files)),
        &no_lens(),
        &mut pipeline::no_progress,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("frame_1.jpg") && err.contains("RAW"), "{err}");
}

/// Truncated files and files with bad tags give a one-line error naming the file, never a
/// panic; so does every single-byte corruption of the header region.
#[test]
fn malformed_dngs_give_one_line_errors() {
    let truth = scene(32, 4);
    let files = synth::raw_bracket(&truth, &RawSynthOptions::default()).unwrap();
    let good = &files[0].1;
    let opts = DecodeOptions::default();
    let check = |bytes: &[u8], what: &str| {
        let r = bracket::decode("bad.dng", bytes, &opts);
        if let Err(e) = r {
            let m = e.to_string();
            assert!(m.starts_with("bad.dng: "), "{what}: {m}");
            assert!(!m.contains('\n'), "{what}: {m}");
            Some(m)
        } else {
            None
        }
    };
    // Truncated anywhere after the header: the data or the IFD is gone.
    for cut in [16, good.len() / 3, good.len() / 2] {
        let m = check(&good[..cut], "truncated").expect("a truncated DNG is refused");
        eprintln!("truncated at {cut}: {m}");
    }
    // Bad tags: the CFA pattern names a fourth colour; the white level is below black.
    let patch = |tag: u16, value: u16| -> Vec<u8> {
        let mut b = good.clone();
        let ifd = u32::from_le_bytes([b[4], b[5], b[6], b[7]]) as usize;
        let count = u16::from_le_bytes([b[ifd], b[ifd + 1]]) as usize;
        for i in 0..count {
            let e = ifd + 2 + 12 * i;
            if u16::from_le_bytes([b[e], b[e + 1]]) == tag {
                b[e + 8..e + 10].copy_from_slice(&value.to_le_bytes());
            }
        }
        b
    };
    let m = check(&patch(33422, 0x0303), "bad CFA").expect("a bad CFA is refused");
    assert!(m.contains("CFA"), "{m}");
    let m = check(&patch(50717, 10), "white below black").expect("a bad white level is refused");
    assert!(m.contains("white level"), "{m}");
    let m = check(&patch(258, 4), "4 bits").expect("4-bit samples are refused");
    assert!(m.contains("bits"), "{m}");
    // Every byte of the first 600 set to 0xFF in turn: an error or a frame, never a panic.
    for i in 0..600.min(good.len()) {
        let mut b = good.clone();
        b[i] = 0xFF;
        let _ = check(&b, "corrupt byte");
    }
}

/// Hand-built DNGs in every layout the reader takes (strips, tiles, 8/16-bit, packed 12/14-bit,
/// lossless JPEG with one, two and three components, LinearRaw, a linearisation table, a 2 × 2
/// black-level pattern, an active area, a SubIFD, big-endian) decode to the values written:
/// every measured photosite equals `(lin(raw) − black) / (white − black)` within one 16-bit code.
#[test]
fn dngs_in_every_layout_decode_to_the_values_written() {
    use crate::dng_build::{dng, sample, specs};
    for (name, spec) in specs() {
        let bytes = dng(&spec);
        let (f, colour) = bracket::dng::decode_dng(name, &bytes, &DecodeOptions::default())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let [top, left, bottom, right] = spec
            .active_area
            .unwrap_or([0, 0, spec.height as u32, spec.width as u32])
            .map(|v| v as usize);
        assert_eq!(
            (f.width, f.height),
            (right - left, bottom - top),
            "{name}: size"
        );
        assert_eq!(f.exif_time_s.is_some(), spec.exif, "{name}: EXIF time");
        let Pixels::U16(px) = &f.pixels else {
            panic!("{name}: RAW frames are 16-bit")
        };
        let (mut checked, mut worst) = (0usize, 0f32);
        for y in 0..f.height {
            for x in 0..f.width {
                let (sx, sy) = (x + left, y + top);
                for s in 0..spec.spp {
                    let c = if spec.spp == 1 {
                        usize::from(spec.cfa[(sy & 1) * 2 + (sx & 1)])
                    } else {
                        s
                    };
                    assert!(colour.native(x, y, c), "{name}: CFA phase at ({x}, {y})");
                    let raw = sample(&spec, sx, sy, s);
                    let lin = spec
                        .linearization
                        .as_ref()
                        .map_or(f32::from(raw), |t| f32::from(t[usize::from(raw)]));
                    let black = match spec.black_dim {
                        Some((_, cols)) => {
                            spec.black[(sy % 2) * usize::from(cols) + sx % usize::from(cols)]
                        }
                        None => spec.black[0],
                    } as f32;
                    let want = (lin - black) / (spec.white as f32 - black);
                    let got = bracket::dng::raw_value(px[(y * f.width + x) * 3 + c]);
                    if want >= bracket::dng::CLIP_FRACTION {
                        assert_eq!(got, None, "{name}: ({x}, {y}) should be clipped");
                    } else {
                        let got = got.unwrap_or_else(|| panic!("{name}: ({x}, {y}) clipped"));
                        // Below black, the codes stop at 0.
                        let floor = -f32::from(bracket::dng::RAW_PEDESTAL)
                            / f32::from(bracket::dng::RAW_FULL - bracket::dng::RAW_PEDESTAL);
                        worst = worst.max((got - want.max(floor)).abs());
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 50, "{name}: only {checked} photosites checked");
        assert!(worst <= 1.0 / 63486.0, "{name}: off by {worst:e}");
    }
}

/// Damaged sizes are refused before anything is allocated for them: a lossless JPEG tile whose
/// frame header announces 65535 × 65535 pixels (the decoder would reserve 8 GB; fuzzing
/// `read_dng` found a smaller one that reserved 1.8 GB) and a tile size far beyond the image's.
#[test]
fn a_tile_header_announcing_more_pixels_than_the_tile_is_refused() {
    use crate::dng_build::{dng, Layout, Spec};
    let good = dng(&Spec::cfa(20, 12, 14, Layout::Ljpeg { w: 16, h: 8 }));
    let opts = DecodeOptions::default();
    assert!(bracket::decode("ok.dng", &good, &opts).is_ok());

    // Every SOF3 header (FF C3, length, precision, then height and width) set to 65535 × 65535.
    let mut big = good.clone();
    let mut patched = 0;
    for i in 0..big.len() - 9 {
        if big[i] == 0xFF && big[i + 1] == 0xC3 {
            big[i + 5..i + 9].copy_from_slice(&[0xFF; 4]);
            patched += 1;
        }
    }
    assert!(patched >= 2, "{patched} lossless JPEG tiles found");
    let m = bracket::decode("big.dng", &big, &opts)
        .expect_err("a frame header larger than its tile is refused")
        .to_string();
    assert!(m.starts_with("big.dng: ") && m.contains("announces"), "{m}");
    assert!(!m.contains('\n'), "{m}");

    // TileWidth (322) set to 65535: a 65535 × 8 tile for a 20 × 12 image.
    let mut wide = good.clone();
    let ifd = u32::from_le_bytes([wide[4], wide[5], wide[6], wide[7]]) as usize;
    let count = u16::from_le_bytes([wide[ifd], wide[ifd + 1]]) as usize;
    let mut found = false;
    for i in 0..count {
        let e = ifd + 2 + 12 * i;
        if u16::from_le_bytes([wide[e], wide[e + 1]]) == 322 {
            wide[e + 8..e + 12].copy_from_slice(&[0xFF, 0xFF, 0, 0]);
            found = true;
        }
    }
    assert!(found, "TileWidth tag in IFD0");
    let m = bracket::decode("wide.dng", &wide, &opts)
        .expect_err("a tile far larger than the image is refused")
        .to_string();
    assert!(
        m.starts_with("wide.dng: ") && m.contains("tile of 65535"),
        "{m}"
    );
}
