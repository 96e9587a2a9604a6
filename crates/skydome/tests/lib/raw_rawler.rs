//! Camera RAW files: refused with a message saying how to read them in the default build;
//! with the opt-in `raw-rawler` feature, read through rawler onto the DNG path (the same
//! pixels as our own DNG reader), and malformed files give one-line errors, never a crash.
//!
//! No real non-DNG camera RAW file with a licence that allows it is available to the tests
//! (`../shared/data/raw_dng/SOURCE.txt`: the CR2 twins of frobisher_001 are not obtainable
//! here), so the rawler route is checked on DNGs (the real tinydng sample and synthetic
//! brackets) and on malformed camera-RAW containers.

use skydome::bracket::{self, DecodeOptions};
use skydome::synth::{self, RawSynthOptions};

/// A camera RAW's first bytes, for each signature the reader recognises, as `(name, bytes)`.
fn camera_raw_headers() -> Vec<(&'static str, Vec<u8>)> {
    let mut cr2 = b"II*\0\x10\0\0\0CR\x02\0\0\0\0\0".to_vec();
    cr2.extend_from_slice(&[0u8; 64]);
    let mut cr3 = b"\0\0\0\x18ftypcrx \0\0\0\x01crx isom".to_vec();
    cr3.extend_from_slice(&[0u8; 64]);
    let mut raf = b"FUJIFILMCCD-RAW 0201FF383501".to_vec();
    raf.extend_from_slice(&[0u8; 128]);
    let mut orf = b"IIRO\x08\0\0\0".to_vec();
    orf.extend_from_slice(&[0u8; 64]);
    let mut rw2 = b"IIU\0\x08\0\0\0".to_vec();
    rw2.extend_from_slice(&[0u8; 64]);
    // A NEF is a TIFF: recognised by its extension.
    let mut nef = b"MM\0*\0\0\0\x08\0\x01\x01\x0f\0\x02\0\0\0\x06\0\0\0\x1aNIKON\0".to_vec();
    nef.extend_from_slice(&[0u8; 64]);
    vec![
        ("IMG_0001.CR2", cr2),
        ("IMG_0001.CR3", cr3),
        ("DSCF0001.RAF", raf),
        ("P0000001.ORF", orf),
        ("P0000001.RW2", rw2),
        ("DSC_0001.NEF", nef),
    ]
}

fn check_one_line(name: &str, r: Result<bracket::DecodedFrame, bracket::BracketError>) -> String {
    let m = r
        .err()
        .unwrap_or_else(|| panic!("{name}: a malformed file was accepted"))
        .to_string();
    assert!(m.starts_with(&format!("{name}: ")), "{m}");
    assert!(!m.contains('\n'), "{m}");
    m
}

#[cfg(not(feature = "raw-rawler"))]
#[test]
fn camera_raw_is_refused_with_a_way_to_read_it_in_the_default_build() {
    for (name, bytes) in camera_raw_headers() {
        let m = check_one_line(
            name,
            bracket::decode(name, &bytes, &DecodeOptions::default()),
        );
        assert!(
            m.contains("camera RAW") && m.contains("raw-rawler") && m.contains("DNG"),
            "{m}"
        );
        eprintln!("{m}");
    }
    // A DNG is read in every build.
    let files =
        synth::raw_bracket(&synth::scene(16, 16, 1, None), &RawSynthOptions::default()).unwrap();
    assert!(bracket::decode("x.dng", &files[0].1, &DecodeOptions::default()).is_ok());
}

#[cfg(feature = "raw-rawler")]
mod with_rawler {
    use super::*;
    use crate::common::required::shared_data;
    use skydome::bracket::{dng, Pixels};

    fn codes(f: &bracket::DecodedFrame) -> &[u16] {
        match &f.pixels {
            Pixels::U16(p) => p,
            Pixels::U8(_) => panic!("RAW frames are 16-bit"),
        }
    }

    /// The two readers' frames of one DNG: same size, CFA, levels, colour, and pixels within
    /// `tol` of a raw value (1 = white level); returns the largest difference.
    fn compare(name: &str, bytes: &[u8], tol: f32) -> f32 {
        let opts = DecodeOptions::default();
        let (ours, c_ours) = dng::decode_dng(name, bytes, &opts).unwrap();
        let (theirs, c_theirs) = bracket::decode_with_rawler(name, bytes, &opts).unwrap();
        assert_eq!(
            (theirs.width, theirs.height),
            (ours.width, ours.height),
            "{name}: size"
        );
        assert_eq!(c_theirs.cfa, c_ours.cfa, "{name}: CFA");
        assert_eq!(c_theirs.black_level, c_ours.black_level, "{name}: black");
        assert_eq!(c_theirs.white_level, c_ours.white_level, "{name}: white");
        for c in 0..3 {
            assert!(
                (c_theirs.as_shot_neutral[c] - c_ours.as_shot_neutral[c]).abs() < 1e-4,
                "{name}: neutral {:?} vs {:?}",
                c_theirs.as_shot_neutral,
                c_ours.as_shot_neutral
            );
            for k in 0..3 {
                let (a, b) = (
                    c_theirs.camera_to_rec709[c][k],
                    c_ours.camera_to_rec709[c][k],
                );
                assert!(
                    (a - b).abs() < 1e-4,
                    "{name}: camera → Rec.709 [{c}][{k}] {a} vs {b}"
                );
            }
        }
        // Exposure EXIF.
        assert_eq!(theirs.exif_time_s, ours.exif_time_s, "{name}: time");
        assert_eq!(theirs.iso, ours.iso, "{name}: ISO");
        assert_eq!(theirs.f_number, ours.f_number, "{name}: f-number");
        let (a, b) = (codes(&ours), codes(&theirs));
        assert_eq!(a.len(), b.len());
        let mut worst = 0f32;
        let mut clipped_differ = 0usize;
        for (&x, &y) in a.iter().zip(b) {
            match (dng::raw_value(x), dng::raw_value(y)) {
                (Some(u), Some(v)) => worst = worst.max((u - v).abs()),
                (None, None) => {}
                _ => clipped_differ += 1,
            }
        }
        assert_eq!(clipped_differ, 0, "{name}: clipped in one reader only");
        assert!(worst <= tol, "{name}: largest difference {worst:e}");
        eprintln!(
            "{name}: {}×{} through rawler = our DNG reader within {worst:.2e} of the white level; matrix {} / {}",
            ours.width, ours.height, c_theirs.matrix_from, c_ours.matrix_from
        );
        worst
    }

    #[test]
    fn the_real_dng_through_rawler_equals_our_dng_reader() {
        let Some(dir) = shared_data("raw_dng") else {
            return;
        };
        let bytes = std::fs::read(dir.join("tinydng_colorchart.dng")).unwrap();
        // 14-bit data: the 16-bit codes of both readers round the same values; one code step
        // is 1/63486 of the white level.
        compare("tinydng_colorchart.dng", &bytes, 2.0 / 63486.0);
    }

    /// The real RAW bracket (`scripts/fetch-raw-bracket.sh`): Adobe-converted DNGs whose
    /// lossless JPEG tiles have two components, which our own decoder reads
    /// (`bracket::ljpeg`); rawler's decoder is the independent reference.
    #[test]
    fn the_real_raw_bracket_through_rawler_equals_our_dng_reader() {
        let Some(dir) = crate::common::required::raw_bracket() else {
            return;
        };
        for name in ["sample1.dng", "sample2.dng", "sample3.dng"] {
            let bytes = std::fs::read(dir.join(name)).unwrap();
            assert_eq!(compare(name, &bytes, 0.0), 0.0);
        }
    }

    #[test]
    fn synthetic_dngs_through_rawler_equal_our_dng_reader() {
        for (seed, cfa, neutral) in [
            (1u64, [0u8, 1, 1, 2], None),
            (2, [1, 0, 2, 1], Some([0.5, 1.0, 0.7])),
            (3, [2, 1, 1, 0], Some([0.45, 1.0, 0.8])),
        ] {
            let opts = RawSynthOptions {
                seed,
                cfa,
                neutral,
                colour_matrix: Some([0.9, -0.3, -0.1, -0.4, 1.2, 0.2, -0.05, 0.15, 0.6]),
                ..RawSynthOptions::default()
            };
            let scene = synth::scene(48, 40, seed, None);
            for (name, bytes) in synth::raw_bracket(&scene, &opts).unwrap() {
                compare(&name, &bytes, 2.0 / 63486.0);
            }
        }
    }

    /// Truncated and corrupted files through rawler: a one-line error naming the file (or a
    /// frame), never a panic out of the reader. rawler panics on some of these (caught and
    /// reported as errors); the count is printed.
    #[test]
    fn malformed_files_through_rawler_give_one_line_errors() {
        let opts = DecodeOptions::default();
        let mut errors = 0;
        let mut panicked = 0;
        let mut run = |name: &str, bytes: &[u8]| {
            let r = std::panic::catch_unwind(|| bracket::decode_with_rawler(name, bytes, &opts));
            let r = r.unwrap_or_else(|_| panic!("{name}: rawler's panic escaped"));
            if let Err(e) = r {
                let m = e.to_string();
                assert!(m.starts_with(&format!("{name}: ")), "{m}");
                assert!(!m.contains('\n'), "{m}");
                errors += 1;
                panicked += usize::from(m.contains("panic"));
            }
        };
        // Camera RAW containers with nothing after their header, truncated at every length.
        for (name, bytes) in camera_raw_headers() {
            for cut in 0..bytes.len() {
                run(name, &bytes[..cut]);
            }
            run(name, &bytes);
        }
        // A synthetic DNG truncated at many lengths and with bytes of its header region
        // overwritten.
        let files = synth::raw_bracket(&synth::scene(32, 32, 4, None), &RawSynthOptions::default())
            .unwrap();
        let good = &files[0].1;
        for cut in (0..good.len()).step_by(97) {
            run("cut.dng", &good[..cut]);
        }
        for i in 0..600.min(good.len()) {
            for v in [0x00, 0xFF, 0x7F] {
                let mut b = good.clone();
                b[i] = v;
                run("corrupt.dng", &b);
            }
        }
        eprintln!(
            "rawler: {errors} malformed inputs refused, {panicked} of them by a caught panic"
        );
        assert!(errors > 100);
    }

    /// Through [`bracket::decode`], a camera RAW file goes to rawler (not the TIFF reader) and
    /// its error names the file.
    #[test]
    fn camera_raw_files_are_routed_to_rawler() {
        for (name, bytes) in camera_raw_headers() {
            let m = check_one_line(
                name,
                bracket::decode(name, &bytes, &DecodeOptions::default()),
            );
            assert!(!m.contains("raw-rawler"), "{m}");
            eprintln!("{m}");
        }
    }

    /// A RAW above the pixel limit is refused from its header, before its pixels are decoded.
    #[test]
    fn the_pixel_limit_holds_for_rawler() {
        let files = synth::raw_bracket(&synth::scene(64, 64, 2, None), &RawSynthOptions::default())
            .unwrap();
        let e = bracket::decode_with_rawler(
            "big.dng",
            &files[0].1,
            &DecodeOptions { max_pixels: 1000 },
        )
        .unwrap_err();
        assert!(matches!(e, bracket::BracketError::TooLarge { .. }), "{e}");
    }
}
