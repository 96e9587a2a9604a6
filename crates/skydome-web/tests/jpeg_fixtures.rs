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

/// Damaged copies of four fixtures (baseline 4:2:0, restart markers, progressive, 4:4:4): a tenth
/// of the file cut out of the entropy-coded data (40–50 %), a byte of it flipped, a stray
/// restart marker or fill bytes before a stuffed byte (0xFF 0xFF 0x00) inserted. (A file cut
/// short is refused before it reaches the decoder: no end-of-image marker.) zune-jpeg decodes
/// them anyway (not strict, as `image` asks) into pixels that depend on exactly when its bit
/// reader meets the damage, so they pin down its refill: the skydome patch reads the
/// entropy-coded data through a window of 64 bytes (vendor/zune-jpeg/PATCHED.md, third round)
/// and must decode every byte as zune-jpeg 0.5.15 did. The digests are those of the unpatched
/// decoder (main before that patch, `web-tests/decode-bench` built from it, the same FNV-1a of
/// the same RGB pixels), which the patched one matched on 485 such files.
#[test]
fn damaged_jpeg_fixtures_decode_as_the_unpatched_decoder_did() {
    type Damage = fn(&[u8]) -> Vec<u8>;
    let at = |d: &[u8], percent: usize| d.len() * percent / 100;
    let damages: [(&str, Damage); 4] = [
        ("gap", |d| {
            let mut b = d[..d.len() * 40 / 100].to_vec();
            b.extend_from_slice(&d[d.len() * 50 / 100..]);
            b
        }),
        ("xor60", |d| {
            let mut b = d.to_vec();
            b[d.len() * 60 / 100] ^= 0x5A;
            b
        }),
        ("rst45", |d| {
            let mut b = d.to_vec();
            let p = d.len() * 45 / 100;
            b.splice(p..p, [0xFF, 0xD3]);
            b
        }),
        ("fill55", |d| {
            let mut b = d.to_vec();
            let p = d.len() * 55 / 100;
            b.splice(p..p, [0xFF, 0xFF, 0x00]);
            b
        }),
    ];
    // (fixture, FNV-1a 64 of the RGB pixels per damage) from the unpatched decoder.
    let expected = [
        (
            "rgb420_203x151",
            [
                "6e0edb37ec4d377d",
                "f8f91c367fadd34a",
                "3cda955954b59da2",
                "c179b74ea4d49ec4",
            ],
        ),
        (
            "rgb420_restart3_131x67",
            [
                "241a1de9e47f292a",
                "a9f704908422357c",
                "0559158b00a858ac",
                "9760942c9775d89c",
            ],
        ),
        (
            "rgb444_progressive_99x64",
            [
                "f4f3737a8fe999d7",
                "88bbd74b13f05781",
                "8692c711d3e51cf8",
                "fa00c4408868c185",
            ],
        ),
        (
            "rgb444_61x45",
            [
                "e2ec6477b39cd692",
                "75accbff270b6abf",
                "380a6f107c55a95b",
                "c0b5c5133d9e29aa",
            ],
        ),
    ];
    let dir = fixtures_dir();
    for (name, digests) in expected {
        let file = format!("{name}.jpg");
        let bytes = std::fs::read(dir.join(&file)).expect("fixture");
        // the damage lands after the first start-of-scan header (in a progressive file also in
        // later scans' headers)
        let sos = bytes
            .windows(2)
            .position(|m| m == [0xFF, 0xDA])
            .expect("SOS");
        assert!(
            at(&bytes, 40) > sos + 14,
            "{file}: damage before the first scan"
        );
        for ((what, damage), digest) in damages.iter().zip(digests) {
            let damaged = damage(&bytes);
            let (_, pixels) = skydome_web::decode_split(&file, &damaged)
                .unwrap_or_else(|e| panic!("{file} {what}: {e}"));
            assert_eq!(fnv1a64(&pixels), digest, "{file} {what}");
        }
    }
}
