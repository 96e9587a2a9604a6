//! A real RAW bracket: HDRMerge's three test DNGs (Nikon D5000, 1/640, 1/160 and 1/40 s,
//! hand-held; Adobe-converted, lossless JPEG tiles of two components), fetched from Debian's
//! source package by `scripts/fetch-raw-bracket.sh` (see its SOURCE.txt). Each frame agrees
//! with the merge and with its neighbour at the exposure ratio EXIF states; and the lossless
//! JPEG decoder that reads those tiles decodes every predictor, component count, point
//! transform and restart interval to the samples written.

use skydome::bracket::{self, dng, ljpeg, DecodeOptions, Frame, Pixels, RawColour};
use skydome::pipeline::{self, EncodedFrame, Frames, Input};
use skydome::{align, merge};

use crate::common::required::raw_bracket;
use crate::dng_build::{ljpeg_with, Coding};

/// The bracket shortest first, as the pipeline sorts it.
const FILES: [&str; 3] = ["sample2.dng", "sample1.dng", "sample3.dng"];

/// Lossless JPEG streams of every predictor (1–7), 1–4 components, point transforms 0 and 2,
/// with and without restart markers, decode to the samples written; asked for fewer samples,
/// the decoder gives their prefix.
#[test]
fn lossless_jpeg_streams_decode_to_the_samples_written() {
    let (w, h) = (13usize, 9usize);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut streams = 0;
    for comps in 1..=4 {
        for predictor in 1..=7u8 {
            for (bits, pt) in [(14usize, 0usize), (16, 0), (12, 2)] {
                for restart in [0usize, 4] {
                    // A ramp with noise: every difference category occurs.
                    let s: Vec<u16> = (0..w * h * comps)
                        .map(|i| {
                            let ramp = (i * 37) as u64 % (1 << bits);
                            let v = (ramp ^ (next() % 512)) % (1 << bits);
                            ((v >> pt) << pt) as u16
                        })
                        .collect();
                    let coding = Coding {
                        predictor,
                        pt,
                        restart_rows: restart,
                    };
                    let bytes = ljpeg_with(&s, w, h, comps, bits, coding);
                    let d = ljpeg::decode(&bytes, usize::MAX).unwrap_or_else(|e| {
                        panic!("{comps} comps, predictor {predictor}, pt {pt}: {e}")
                    });
                    assert_eq!((d.width, d.height, d.components), (w, h, comps));
                    assert_eq!(
                        d.samples, s,
                        "{comps} components, predictor {predictor}, {bits}-bit, pt {pt}, restart {restart}"
                    );
                    let part = ljpeg::decode(&bytes, 50).unwrap();
                    assert_eq!(part.samples, s[..50]);
                    assert_eq!(ljpeg::component_count(&bytes), Some(comps));
                    streams += 1;
                }
            }
        }
    }
    assert_eq!(streams, 4 * 7 * 3 * 2);
    // Cut streams are errors, never panics.
    let s: Vec<u16> = (0..w * h * 2).map(|i| (i * 97 % 4096) as u16).collect();
    let bytes = crate::dng_build::ljpeg(&s, w, h, 2, 12);
    for n in 0..bytes.len() - 2 {
        assert!(
            ljpeg::decode(&bytes[..n], usize::MAX).is_err(),
            "cut at {n}"
        );
    }
    // Damaged bytes: an error or some samples, never a panic (nor a huge allocation: the
    // header may announce 65535 × 65535 pixels).
    for i in 0..bytes.len() {
        for b in [0x00, 0x7F, 0xFF] {
            let mut d = bytes.clone();
            d[i] = b;
            if let Ok(l) = ljpeg::decode(&d, usize::MAX) {
                assert!(l.samples.len() <= 8 * d.len(), "byte {i} = {b:#x}");
            }
        }
    }
}

fn values(f: &Frame) -> &[u16] {
    match &f.pixels {
        Pixels::U16(v) => v,
        Pixels::U8(_) => panic!("RAW frames are 16-bit"),
    }
}

/// The inverse of a 3 × 3 matrix.
fn inverse(m: [[f32; 3]; 3]) -> [[f64; 3]; 3] {
    let a = m.map(|r| r.map(f64::from));
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    let mut inv = [[0f64; 3]; 3];
    for (i, row) in inv.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            let (r0, r1) = ((j + 1) % 3, (j + 2) % 3);
            let (c0, c1) = ((i + 1) % 3, (i + 2) % 3);
            *v = (a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]) / det;
        }
    }
    inv
}

fn median(mut v: Vec<f64>) -> f64 {
    assert!(!v.is_empty());
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Per frame, over its measured (not interpolated), well-exposed photosites (5 %–80 % of the
/// white level), the median `|log2(v / t − E)|` in stops, `E` the merge in camera RGB.
fn frame_consistency(frames: &[Frame], colour: &RawColour, m: &merge::LinearMerged) -> Vec<f64> {
    let inv = inverse(colour.camera_to_rec709);
    let (w, h) = (frames[0].width, frames[0].height);
    frames
        .iter()
        .map(|f| {
            let t = f.exposure.relative();
            let v = values(f);
            let mut d = Vec::new();
            // Every 7th row and column: 200 000 photosites are plenty for a median.
            for y in (0..h).step_by(7) {
                for x in (0..w).step_by(7) {
                    let k = y * w + x;
                    let rgb = &m.radiance.data[3 * k..3 * k + 3];
                    for c in (0..3).filter(|&c| colour.native(x, y, c)) {
                        let Some(val) = dng::raw_value(v[3 * k + c]) else {
                            continue;
                        };
                        let e: f64 = (0..3).map(|j| inv[c][j] * f64::from(rgb[j])).sum();
                        if (0.05..0.8).contains(&val) && e > 0.0 && m.clipped[k] == 0 {
                            d.push((f64::from(val) / t / e).log2().abs());
                        }
                    }
                }
            }
            median(d)
        })
        .collect()
}

/// The real RAW bracket decodes (size, CFA, levels, EXIF times), merges through the library
/// with every frame consistent with the merge, and adjacent frames' photosites differ by the
/// exposure ratio EXIF states.
#[test]
fn real_raw_bracket_merges_consistently() {
    let Some(dir) = raw_bracket() else {
        return;
    };
    let encoded: Vec<EncodedFrame> = FILES
        .iter()
        .map(|n| EncodedFrame {
            name: n.to_string(),
            bytes: std::fs::read(dir.join(n)).unwrap(),
        })
        .collect();
    let (first, colour) =
        bracket::decode_raw(FILES[0], &encoded[0].bytes, &DecodeOptions::default()).unwrap();
    let colour = colour.expect("a DNG has a colour");
    assert_eq!((first.width, first.height), (4310, 2868));
    assert_eq!(colour.cfa, Some([1, 2, 0, 1]), "GBRG");
    assert_eq!((colour.black_level, colour.white_level), (0.0, 3840.0));
    assert_eq!(first.iso, Some(200.0));
    let br = pipeline::load_bracket(
        Input::new(Frames::Encoded(encoded)),
        &mut pipeline::no_progress,
    )
    .unwrap();
    let times: Vec<f64> = br.frames.iter().map(|f| f.exposure.time_s).collect();
    for (t, want) in times.iter().zip([1.0 / 640.0, 1.0 / 160.0, 1.0 / 40.0]) {
        assert!((t / want - 1.0).abs() < 1e-6, "times {times:?}");
    }
    let m = merge::merge_linear(&br.frames, &colour, None).unwrap();
    let cons = frame_consistency(&br.frames, &colour, &m);
    // Adjacent frames: the median log2 ratio of a photosite's values, against EXIF's 2 stops.
    let (w, h) = (br.frames[0].width, br.frames[0].height);
    let mut ratio_err = Vec::new();
    for j in 0..2 {
        let (a, b) = (values(&br.frames[j]), values(&br.frames[j + 1]));
        let mut r = Vec::new();
        for y in (0..h).step_by(5) {
            for x in (0..w).step_by(5) {
                let k = y * w + x;
                for c in (0..3).filter(|&c| colour.native(x, y, c)) {
                    if let (Some(u), Some(v)) =
                        (dng::raw_value(a[3 * k + c]), dng::raw_value(b[3 * k + c]))
                    {
                        if u > 0.01 && (0.05..0.8).contains(&v) {
                            r.push(f64::from(v / u).log2());
                        }
                    }
                }
            }
        }
        let n = r.len();
        let stops = median(r);
        let exif = (times[j + 1] / times[j]).log2();
        eprintln!(
            "frames {j}→{}: median log2 ratio {stops:.3} over {n} photosites, EXIF {exif:.3}",
            j + 1
        );
        ratio_err.push(stops - exif);
    }
    // The bracket is hand-held: aligned (whole-pixel shifts against the middle frame, even ones
    // so the frames keep the mosaic's phase, as `pipeline::run` aligns a RAW bracket), the
    // frames agree better and the noise fit no longer takes motion for shot noise.
    let mut frames = br.frames.clone();
    let even = align::AlignOptions {
        even: true,
        ..align::AlignOptions::default()
    };
    let al = align::align_bracket(&mut frames, &even);
    assert!(
        al.shifts.iter().all(|&(x, y)| x % 2 == 0 && y % 2 == 0),
        "{:?}",
        al.shifts
    );
    let ma = merge::merge_linear(&frames, &colour, None).unwrap();
    let cons_al = frame_consistency(&frames, &colour, &ma);
    eprintln!(
        "real RAW bracket (Nikon D5000): frame consistency {cons:.3?} stops, aligned {cons_al:.3?} \
         (shifts {:?}); ratio error {ratio_err:.3?} stops; green noise a {:.2e} ({:.0} e- at white), \
         aligned {:.2e} ({:.0} e-), b {:.1e}; clipped high {} low {}",
        al.shifts,
        m.noise.a[1],
        1.0 / m.noise.a[1],
        ma.noise.a[1],
        1.0 / ma.noise.a[1],
        ma.noise.b[1],
        ma.clipped_high,
        ma.clipped_low
    );
    for (j, e) in ratio_err.iter().enumerate() {
        assert!(
            e.abs() < 0.1,
            "frames {j}→{}: ratio off by {e:.3} stops",
            j + 1
        );
    }
    for (j, (c, ca)) in cons.iter().zip(&cons_al).enumerate() {
        assert!(*c < 0.06, "frame {j}: median |log2(v/t / E)| {c:.3} stops");
        assert!(
            *ca < 0.04,
            "frame {j} aligned: median |log2(v/t / E)| {ca:.3} stops"
        );
    }
    assert!(al.largest() > 0 && al.largest() <= 16, "{:?}", al.shifts);
    assert!(ma.noise.fitted);
    // A 12-bit APS-C sensor at ISO 200: thousands of electrons at the white level (the
    // unaligned fit, which counts motion as noise, gives ten times fewer).
    let electrons = 1.0 / ma.noise.a[1];
    assert!((1500.0..20000.0).contains(&electrons), "{electrons:.0} e-");
    assert!(m.noise.a[1] > 3.0 * ma.noise.a[1]);
}
