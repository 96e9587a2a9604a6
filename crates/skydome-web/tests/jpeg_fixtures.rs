//! The JPEGs that prove the phone app decodes exactly as the command line does.
//!
//! The app's JPEG decoder (zune-jpeg, vendor/zune-jpeg) runs WebAssembly SIMD code for the
//! IDCT and the colour conversion where the native build runs AVX2, NEON or scalar code
//! (vendor/zune-jpeg/PATCHED.md). The two must give the same pixels, code for code. This test
//! makes a set of JPEGs covering the decoder's paths (4:4:4, 4:2:2, 4:2:0, 4:4:0, greyscale,
//! progressive, restart intervals, odd sizes, a width below 16, low and maximum quality,
//! saturated colours that clamp) with the `jpeg-encoder` crate, checks that they are the files
//! kept in `web-tests/fixtures/jpeg/`, decodes them natively through the web crate's own
//! decoding step ([`skydome_web::decode_split`]) and checks the pixels' digests against
//! `native.json` there. The browser-side test (`web-tests/tests/decode.test.mjs`) decodes the
//! same files in the built wasm and checks the same digests, so native and wasm agree exactly.
//!
//! After a deliberate change of the encoder or of the native decoder, rewrite the files with
//! `SKYDOME_BLESS_JPEG_FIXTURES=1 cargo test --workspace --test jpeg_fixtures`.

use std::collections::BTreeMap;
use std::path::PathBuf;

use jpeg_encoder::{ColorType, Encoder, SamplingFactor};

/// One fixture: how it is encoded.
struct Case {
    name: &'static str,
    width: u16,
    height: u16,
    grey: bool,
    sampling: SamplingFactor,
    quality: u8,
    progressive: bool,
    restart: u16,
}

const fn case(name: &'static str, width: u16, height: u16, sampling: SamplingFactor) -> Case {
    Case {
        name,
        width,
        height,
        grey: false,
        sampling,
        quality: 90,
        progressive: false,
        restart: 0,
    }
}

fn cases() -> Vec<Case> {
    vec![
        case("rgb444_61x45", 61, 45, SamplingFactor::F_1_1),
        case("rgb422_150x97", 150, 97, SamplingFactor::F_2_1),
        case("rgb420_203x151", 203, 151, SamplingFactor::F_2_2),
        case("rgb440_77x90", 77, 90, SamplingFactor::F_1_2),
        Case {
            grey: true,
            ..case("grey_97x73", 97, 73, SamplingFactor::F_1_1)
        },
        Case {
            progressive: true,
            ..case(
                "rgb420_progressive_160x120",
                160,
                120,
                SamplingFactor::F_2_2,
            )
        },
        Case {
            progressive: true,
            ..case("rgb444_progressive_99x64", 99, 64, SamplingFactor::F_1_1)
        },
        Case {
            restart: 3,
            ..case("rgb420_restart3_131x67", 131, 67, SamplingFactor::F_2_2)
        },
        Case {
            restart: 1,
            ..case("rgb444_restart1_48x40", 48, 40, SamplingFactor::F_1_1)
        },
        case("rgb444_13x9", 13, 9, SamplingFactor::F_1_1),
        Case {
            quality: 100,
            ..case("rgb444_q100_64x48", 64, 48, SamplingFactor::F_1_1)
        },
        Case {
            quality: 25,
            ..case("rgb420_q25_96x80", 96, 80, SamplingFactor::F_2_2)
        },
    ]
}

/// The picture: flat areas (DC-only blocks), smooth gradients (few coefficients), a textured
/// and a noisy band (every coefficient), hard edges and saturated patches whose decoded values
/// clamp at 0 and 255. Deterministic (a fixed integer hash for the noise).
fn picture(w: usize, h: usize) -> Vec<[u8; 3]> {
    let mut px = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (x as f64 / w as f64, y as f64 / h as f64);
            let noise = {
                let mut s =
                    (x as u32).wrapping_mul(0x9E37_79B1) ^ (y as u32).wrapping_mul(0x85EB_CA77);
                s ^= s >> 15;
                s = s.wrapping_mul(0x2C1B_3C6D);
                s ^= s >> 12;
                (s & 0xFF) as u8
            };
            let p = match (x * 4 / w.max(1), y * 3 / h.max(1)) {
                (0, 0) => [40, 90, 200],
                (1, 0) => [(255.0 * fx) as u8, (255.0 * fy) as u8, 128],
                (2, 0) => [255, 0, 0],
                (3, 0) => [0, 0, 255],
                (_, 1) => {
                    let t = ((fx * 37.0).sin() * (fy * 23.0).cos() * 127.0 + 128.0) as u8;
                    [t, 255 - t, t / 2]
                }
                (0 | 1, _) => [noise, noise.wrapping_mul(7), 255 - noise],
                (2, _) => [255, 255, 0],
                _ => match (x / 3 + y / 3) % 2 {
                    0 => [0, 0, 0],
                    _ => [255, 255, 255],
                },
            };
            px.push(p);
        }
    }
    px
}

fn encode(c: &Case) -> Vec<u8> {
    let (w, h) = (usize::from(c.width), usize::from(c.height));
    let px = picture(w, h);
    let mut out = Vec::new();
    let mut enc = Encoder::new(&mut out, c.quality);
    enc.set_sampling_factor(c.sampling);
    enc.set_progressive(c.progressive);
    if c.restart > 0 {
        enc.set_restart_interval(c.restart);
    }
    if c.grey {
        let luma: Vec<u8> = px
            .iter()
            .map(|p| ((u32::from(p[0]) * 3 + u32::from(p[1]) * 6 + u32::from(p[2])) / 10) as u8)
            .collect();
        enc.encode(&luma, c.width, c.height, ColorType::Luma)
            .expect("encode");
    } else {
        let rgb: Vec<u8> = px.iter().flatten().copied().collect();
        enc.encode(&rgb, c.width, c.height, ColorType::Rgb)
            .expect("encode");
    }
    out
}

/// 64-bit FNV-1a of the bytes, as 16 hex digits (web-tests/tests/decode.test.mjs computes the
/// same).
fn fnv1a64(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

fn fixtures_dir() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../web-tests/fixtures/jpeg"
    ))
}

#[test]
fn native_decodes_of_the_jpeg_fixtures_match_their_digests() {
    let dir = fixtures_dir();
    let bless = std::env::var_os("SKYDOME_BLESS_JPEG_FIXTURES").is_some_and(|v| v == "1");
    let mut digests = BTreeMap::new();
    for c in cases() {
        let file = format!("{}.jpg", c.name);
        let bytes = encode(&c);
        let path = dir.join(&file);
        if bless {
            std::fs::create_dir_all(&dir).expect("fixtures folder");
            std::fs::write(&path, &bytes).expect("write fixture");
        } else {
            let kept = std::fs::read(&path)
                .unwrap_or_else(|e| panic!("{}: {e} (bless the fixtures)", path.display()));
            assert!(
                kept == bytes,
                "{file}: the kept fixture is not what the encoder writes now (bless the fixtures)"
            );
        }
        let (meta, pixels) = skydome_web::decode_split(&file, &bytes).expect("decode");
        let meta: serde_json::Value = serde_json::from_str(&meta).expect("meta");
        assert_eq!(meta["width"], c.width, "{file}");
        assert_eq!(meta["height"], c.height, "{file}");
        assert_eq!(
            pixels.len(),
            3 * usize::from(c.width) * usize::from(c.height)
        );
        digests.insert(
            file,
            serde_json::json!({ "width": c.width, "height": c.height, "fnv1a64": fnv1a64(&pixels) }),
        );
    }
    let json = serde_json::to_string_pretty(&digests).expect("json") + "\n";
    let native = dir.join("native.json");
    if bless {
        std::fs::write(&native, json).expect("write native.json");
    } else {
        let kept = std::fs::read_to_string(&native)
            .unwrap_or_else(|e| panic!("{}: {e} (bless the fixtures)", native.display()));
        assert_eq!(kept, json, "the native decodes differ from native.json");
    }
}

/// The fixtures exercise what they are meant to: the decoder reports the sampling and the
/// coding process the case asks for (so a changed encoder default cannot silently drop a path).
#[test]
fn the_jpeg_fixtures_have_the_layouts_they_are_named_after() {
    for c in cases() {
        let bytes = encode(&c);
        let sof = bytes
            .windows(2)
            .position(|m| m == [0xFF, 0xC0] || m == [0xFF, 0xC2])
            .expect("a start-of-frame marker");
        assert_eq!(bytes[sof + 1] == 0xC2, c.progressive, "{}", c.name);
        let components = bytes[sof + 9];
        assert_eq!(components, if c.grey { 1 } else { 3 }, "{}", c.name);
        let luma_sampling = bytes[sof + 11];
        let expected = if c.grey {
            0x11
        } else {
            c.sampling as u8 & 0x7F
        };
        assert_eq!(luma_sampling, expected, "{}", c.name);
        let has_restart = bytes.windows(2).any(|m| m == [0xFF, 0xDD]);
        assert_eq!(has_restart, c.restart > 0, "{}", c.name);
    }
}
