//! Camera RAW files (CR2, CR3, NEF, ARW, RAF, ORF, RW2, PEF, …) through
//! [`rawler`](https://crates.io/crates/rawler), dnglab's decoder. Only with the opt-in
//! `raw-rawler` feature: rawler is **LGPL-2.1**, the default build is MIT OR Apache-2.0 (see
//! the README, "Camera RAW", for what that means for a binary built with it).
//!
//! **Why rawler.** It is the maintained Rust decoder of the camera formats (dnglab's; the
//! lossless-JPEG, Canon CRX, Nikon, Sony, Fuji, Olympus and Panasonic compressions), and unlike
//! `rawloader` (also LGPL) it reads the EXIF exposure fields (time, ISO, f-number) of formats
//! whose EXIF a TIFF reader cannot reach (CR3's ISO-BMFF boxes, RAF's header). 0.7 is the newest
//! release that builds with this workspace's `rust-version`.
//!
//! **Same path as DNG.** rawler is used as a *decoder* only: it hands over the sensor's
//! photosites with their black and white levels, the CFA, the XYZ → camera matrix and the
//! as-shot white balance; from there a camera RAW frame takes exactly the path of a DNG read by
//! [`super::dng`] ([`super::dng::SensorImage::develop`]): normalisation to the white level,
//! clipping at [`super::dng::CLIP_FRACTION`] per photosite, **bilinear** demosaicing (the DNG
//! path's), the same 16-bit codes, and [`super::dng::camera_to_rec709`] for the colour. rawler's
//! own development (its demosaic, its colour pipeline) is not used. Exposure time, ISO and
//! f-number come from the file's EXIF (read as for every frame, then from rawler's reading of
//! the file's metadata for whatever that left empty).
//!
//! **What is refused.** Sensors other than a 2 × 2 red-green-blue pattern (Fuji X-Trans's 6 × 6,
//! four-colour CYGM/RGBE sensors), monochrome sensors, images above the pixel limit (checked on
//! rawler's header-only decode, before the pixels are allocated).
//!
//! **Panics.** rawler is a large parser of untrusted, often undocumented formats, and it can
//! panic on malformed files (its own decode entry point catches some; its format detection and
//! metadata readers do not). Every call into it runs under [`std::panic::catch_unwind`], so a
//! bad RAW file is a one-line error naming the file, never a crash of the process (or of the
//! web app's worker). The default panic message on standard error is silenced while rawler runs
//! (see [`quietly`]): the error message is what the user sees.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Once;

use rawler::decoders::RawDecodeParams;
use rawler::imgop::xyz::Illuminant;
use rawler::rawimage::{RawImage, RawPhotometricInterpretation};
use rawler::rawsource::RawSource;

use super::dng::SensorImage;
use super::{BracketError, DecodeOptions, DecodedFrame, RawColour};

/// Decodes a camera RAW file (or a DNG: rawler reads those too, which the tests use to compare
/// the two readers) into a frame of camera-RGB codes and its colour, as
/// [`super::dng::decode_dng`] does for DNG, with the exposure from the file's EXIF.
pub fn decode_with_rawler(
    name: &str,
    bytes: &[u8],
    opts: &DecodeOptions,
) -> Result<(DecodedFrame, RawColour), BracketError> {
    let bad = |reason: String| BracketError::Corrupt {
        file: name.to_string(),
        reason,
    };
    check_tiff_sizes(bytes).map_err(bad)?;
    let src = RawSource::new_from_slice(bytes);
    let params = RawDecodeParams::default();
    let loader = rawler::global_loader();
    // Header only (no pixels allocated): the size is checked before the decode allocates it.
    let head = quietly(|| loader.decode(&src, &params, true))
        .map_err(|p| bad(format!("the camera RAW decoder (rawler) failed: {p}")))?
        .map_err(|e| bad(rawler_reason(&e)))?;
    let pixels = (head.width as u64).saturating_mul(head.height as u64);
    if pixels > opts.max_pixels {
        return Err(BracketError::TooLarge {
            file: name.to_string(),
            width: head.width as u64,
            height: head.height as u64,
            pixels,
            limit: opts.max_pixels,
        });
    }
    let image = quietly(|| loader.decode(&src, &params, false))
        .map_err(|p| bad(format!("the camera RAW decoder (rawler) failed: {p}")))?
        .map_err(|e| bad(rawler_reason(&e)))?;
    let sensor = sensor_image(&image).map_err(bad)?;
    let (mut frame, colour) = sensor.develop(name);
    // EXIF as for every frame (TIFF-based formats), then rawler's reading of the metadata for
    // what that left empty (CR3, RAF, RW2 and others a TIFF reader cannot open).
    super::exif::read_exif(bytes, &mut frame);
    let meta = quietly(|| {
        rawler::get_decoder(&src)
            .ok()
            .and_then(|d| d.raw_metadata(&src, &params).ok())
    })
    .ok()
    .flatten();
    if let Some(meta) = meta {
        fill_exif(&mut frame, &meta.exif, &meta.make, &meta.model);
    }
    // Sensor order: the CFA phase must survive (see `dng`'s module docs).
    frame.info.orientation = 1;
    Ok((frame, colour))
}

/// Refuses a TIFF-structured file (CR2, NEF, ARW, PEF, DNG, ORF, RW2, …) one of whose IFD
/// entries announces more data than the whole file holds.
///
/// rawler allocates an entry's values from its count before reading them, so a count of a few
/// billion makes it ask for tens of gigabytes; an allocation failure aborts the process (in
/// stable Rust it is not a panic, and [`catch_unwind`] cannot catch it). Every IFD reachable
/// from the header is checked here first: the IFD chain, SubIFDs, the EXIF, GPS and Interop
/// IFDs. Makernotes (vendor layouts) and the TIFF blocks inside CR3 and RAF containers are not
/// reached; such a file can still exhaust memory inside rawler (README, "Camera RAW").
fn check_tiff_sizes(bytes: &[u8]) -> Result<(), String> {
    let big = match bytes.get(..2) {
        Some(b"II") => false,
        Some(b"MM") => true,
        _ => return Ok(()),
    };
    let u16_at = |o: usize| -> Option<u16> {
        let b = bytes.get(o..o.checked_add(2)?)?;
        Some(if big {
            u16::from_be_bytes([b[0], b[1]])
        } else {
            u16::from_le_bytes([b[0], b[1]])
        })
    };
    let u32_at = |o: usize| -> Option<u32> {
        let b = bytes.get(o..o.checked_add(4)?)?;
        Some(if big {
            u32::from_be_bytes([b[0], b[1], b[2], b[3]])
        } else {
            u32::from_le_bytes([b[0], b[1], b[2], b[3]])
        })
    };
    let Some(first) = u32_at(4) else {
        return Ok(());
    };
    let len = bytes.len() as u64;
    let mut todo = vec![first as usize];
    let mut seen = std::collections::HashSet::new();
    while let Some(at) = todo.pop() {
        if at == 0 || !seen.insert(at) || seen.len() > 256 {
            continue;
        }
        let Some(n) = u16_at(at) else { continue };
        for i in 0..usize::from(n) {
            let e = at + 2 + 12 * i;
            let (Some(tag), Some(kind), Some(count)) = (u16_at(e), u16_at(e + 2), u32_at(e + 4))
            else {
                break;
            };
            // The largest element size rawler reads for any type is 8 bytes.
            let size: u64 = match kind {
                1 | 2 | 6 | 7 => 1,
                3 | 8 => 2,
                4 | 9 | 11 | 13 => 4,
                _ => 8,
            };
            let total = u64::from(count) * size;
            if total > len {
                return Err(format!(
                    "camera RAW: TIFF tag {tag} announces {total} bytes of data in a {len}-byte file (corrupt?)"
                ));
            }
            // Sub-IFDs: SubIFDs, EXIF, GPS, Interop.
            if matches!(tag, 330 | 34665 | 34853 | 40965) && matches!(kind, 4 | 13) {
                let values = if total <= 4 {
                    e + 8
                } else {
                    u32_at(e + 8).unwrap_or(0) as usize
                };
                for k in 0..(count as usize).min(16) {
                    if let Some(o) = u32_at(values + 4 * k) {
                        todo.push(o as usize);
                    }
                }
            }
        }
        if let Some(next) = u32_at(at + 2 + 12 * usize::from(n)) {
            todo.push(next as usize);
        }
    }
    Ok(())
}

/// rawler's error as one line.
fn rawler_reason(e: &rawler::RawlerError) -> String {
    format!("camera RAW: {}", one_line(&e.to_string()))
}

/// Text on one line, at most 300 characters.
fn one_line(s: &str) -> String {
    let s = s.split_whitespace().collect::<Vec<_>>().join(" ");
    match s.char_indices().nth(300) {
        Some((i, _)) => format!("{}…", &s[..i]),
        None => s,
    }
}

/// The active area of a decoded RAW image, normalised, with its CFA, levels and colour.
fn sensor_image(img: &RawImage) -> Result<SensorImage, String> {
    let (w, h, cpp) = (img.width, img.height, img.cpp);
    let cfa = match (&img.photometric, cpp) {
        (RawPhotometricInterpretation::Cfa(c), 1) => {
            // The pattern's values are colours (0 R, 1 G, 2 B).
            let p = &c.cfa;
            if p.width != 2 || p.height != 2 || !p.is_rgb() {
                return Err(format!(
                    "camera RAW with a {}×{} colour filter pattern {:?}; only 2 × 2 red-green-blue \
                     patterns (Bayer) are read (Fuji X-Trans and four-colour sensors are not)",
                    p.width, p.height, p.name
                ));
            }
            Some(p)
        }
        (RawPhotometricInterpretation::LinearRaw, 3) => None,
        (RawPhotometricInterpretation::BlackIsZero, _) => {
            return Err("monochrome camera RAW is not supported".into());
        }
        _ => {
            return Err(format!(
                "camera RAW with {cpp} samples per pixel is not supported"
            ))
        }
    };
    let data = img.data.as_f32();
    if w.checked_mul(h).and_then(|n| n.checked_mul(cpp)) != Some(data.len()) {
        return Err(format!(
            "camera RAW decoded to {} samples for {w} × {h} × {cpp}",
            data.len()
        ));
    }
    // The active area (inside the image), else the whole sensor.
    let (x0, y0, aw, ah) = match img.active_area {
        Some(r) if r.p.x + r.d.w <= w && r.p.y + r.d.h <= h => (r.p.x, r.p.y, r.d.w, r.d.h),
        _ => (0, 0, w, h),
    };
    if aw < 4 || ah < 4 {
        return Err(format!(
            "camera RAW active area {aw} × {ah} is below 4 × 4 pixels"
        ));
    }
    // Levels: black per repeat position (rows × cols × planes, from the sensor's top-left),
    // white per plane or per 2 × 2 CFA position.
    let bl = &img.blacklevel;
    let black: Vec<f32> = bl.as_vec();
    if bl.width == 0 || bl.height == 0 || bl.cpp == 0 || black.len() != bl.sample_count() {
        return Err("camera RAW with an unusable black level".into());
    }
    let white: Vec<f32> = img.whitelevel.as_vec();
    if white.is_empty() {
        return Err("camera RAW without a white level".into());
    }
    let black_at = |x: usize, y: usize, s: usize| {
        black[((y % bl.height) * bl.width + x % bl.width) * bl.cpp + s % bl.cpp]
    };
    let white_at = |x: usize, y: usize, s: usize| {
        if cpp == 1 && white.len() == 4 {
            white[(y & 1) * 2 + (x & 1)]
        } else {
            white[s.min(white.len() - 1)]
        }
    };
    let mut values = vec![0f32; aw * ah * cpp];
    for y in 0..ah {
        for x in 0..aw {
            for s in 0..cpp {
                let (sx, sy) = (x + x0, y + y0);
                let (b, wl) = (black_at(sx, sy, s), white_at(sx, sy, s));
                if !(b.is_finite() && wl.is_finite() && wl > b) {
                    return Err("camera RAW white level not above its black level".into());
                }
                let r = data[(sy * w + sx) * cpp + s];
                values[(y * aw + x) * cpp + s] = (r - b) / (wl - b);
            }
        }
    }
    let cfa = cfa.map(|p| {
        let at = |dx: usize, dy: usize| p.color_at(y0 + dy, x0 + dx) as u8;
        [at(0, 0), at(1, 0), at(0, 1), at(1, 1)]
    });
    let (matrix, matrix_from) = colour_matrix(img);
    // rawler's white balance is multipliers (R, G, B, E); the neutral is their inverse, green 1.
    let wb = img.wb_coeffs;
    let as_shot_neutral = if wb[..3].iter().all(|v| v.is_finite() && *v > 0.0) {
        [wb[1] / wb[0], 1.0, wb[1] / wb[2]]
    } else {
        [1.0; 3]
    };
    Ok(SensorImage {
        width: aw,
        height: ah,
        values,
        cfa,
        matrix,
        matrix_from,
        as_shot_neutral,
        black_level: black[0],
        white_level: white[0],
    })
}

/// The XYZ → camera matrix for D65 when the file (or rawler's camera database) has one, else a
/// daylight one, else any; `None` without a usable 3 × 3 matrix.
fn colour_matrix(img: &RawImage) -> (Option<[[f64; 3]; 3]>, String) {
    const PREFERRED: [Illuminant; 7] = [
        Illuminant::D65,
        Illuminant::D55,
        Illuminant::D75,
        Illuminant::D50,
        Illuminant::Daylight,
        Illuminant::FineWeather,
        Illuminant::CloudyWeather,
    ];
    let mut keys: Vec<&Illuminant> = img.color_matrix.keys().collect();
    keys.sort();
    let pick = PREFERRED
        .iter()
        .find(|i| img.color_matrix.contains_key(i))
        .or(keys.first().copied());
    match pick.and_then(|i| img.color_matrix.get(i).map(|m| (i, m))) {
        Some((i, m)) if m.len() == 9 && m.iter().all(|v| v.is_finite()) => {
            let m: Vec<f64> = m.iter().map(|&v| f64::from(v)).collect();
            (
                Some([[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]]),
                format!("rawler colour matrix ({i:?})"),
            )
        }
        _ => (
            None,
            "identity (the camera RAW has no 3-colour matrix)".into(),
        ),
    }
}

/// Fills the exposure and capture fields EXIF left empty from rawler's reading of them.
fn fill_exif(frame: &mut DecodedFrame, exif: &rawler::exif::Exif, make: &str, model: &str) {
    let ratio = |r: &rawler::formats::tiff::Rational| {
        (r.d != 0)
            .then(|| f64::from(r.n) / f64::from(r.d))
            .filter(|v| v.is_finite() && *v > 0.0)
    };
    if frame.exif_time_s.is_none() {
        frame.exif_time_s = exif
            .exposure_time
            .as_ref()
            .and_then(ratio)
            .filter(|&t| t <= 86_400.0);
    }
    if frame.f_number.is_none() {
        frame.f_number = exif.fnumber.as_ref().and_then(ratio);
    }
    if frame.iso.is_none() {
        frame.iso = exif
            .iso_speed_ratings
            .map(u32::from)
            .or(exif.iso_speed)
            .or(exif.recommended_exposure_index)
            .filter(|&i| i > 0)
            .map(f64::from);
    }
    let text = |s: &str| Some(s.trim().to_string()).filter(|s| !s.is_empty());
    let info = &mut frame.info;
    if info.make.is_none() {
        info.make = text(make);
    }
    if info.model.is_none() {
        info.model = text(model);
    }
    if info.datetime_original.is_none() {
        info.datetime_original = exif.date_time_original.as_deref().and_then(text);
    }
    if info.subsec_original.is_none() {
        info.subsec_original = exif.sub_sec_time_original.as_deref().and_then(text);
    }
    if info.utc_offset.is_none() {
        info.utc_offset = exif
            .offset_time_original
            .as_deref()
            .or(exif.offset_time.as_deref())
            .and_then(text);
    }
}

/// Panics while quiet sections run are not printed by the panic hook (their payload becomes
/// the error message instead).
static QUIET: AtomicUsize = AtomicUsize::new(0);
static HOOK: Once = Once::new();

/// Runs `f` (a call into rawler) under [`catch_unwind`]: a panic becomes `Err(its message)`.
///
/// rawler can panic on malformed input (see the module docs); a RAW file must never take the
/// process down. While any quiet section runs, the panic hook stays silent: the hook installed
/// here once passes every other panic to the hook that was there before (the default one
/// prints it; a fuzzer's aborts). rawler panics on its own rayon threads too, so the flag is a
/// process-wide count, not a thread-local: a panic elsewhere at the same moment still unwinds
/// as before, only its message on standard error is lost.
fn quietly<R>(f: impl FnOnce() -> R) -> Result<R, String> {
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if QUIET.load(Ordering::SeqCst) == 0 {
                previous(info);
            }
        }));
    });
    QUIET.fetch_add(1, Ordering::SeqCst);
    let r = catch_unwind(AssertUnwindSafe(f));
    QUIET.fetch_sub(1, Ordering::SeqCst);
    r.map_err(|p| {
        let msg = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        format!("it panicked ({})", one_line(&msg))
    })
}
