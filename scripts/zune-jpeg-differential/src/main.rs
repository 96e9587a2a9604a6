//! Decodes each JPEG given, and `ROUNDS − 1` damaged copies of it, with zune-jpeg 0.5.15 as
//! released and with the patched copy in `vendor/zune-jpeg`, and reports any difference: pixels,
//! one decoding where the other errs, or one panicking where the other does not. The damage is
//! drawn from a fixed seed (bit flips, bytes set to 0xFF, restart markers inserted, truncation,
//! stuffed 0xFF 0x00 pairs), 1–8 changes per copy. Damaged copies that differ are written to
//! the working directory as `differs_N.jpg`. Exit status 1 if any differ.
//!
//! Usage: `zune-jpeg-differential ROUNDS FILE...`

use std::panic;
use std::process::ExitCode;

fn released(b: &[u8]) -> Result<Vec<u8>, String> {
    let cursor = released::zune_core::bytestream::ZCursor::new(b);
    released::JpegDecoder::new(cursor)
        .decode()
        .map_err(|e| format!("{e:?}"))
}

fn patched(b: &[u8]) -> Result<Vec<u8>, String> {
    let cursor = patched::zune_core::bytestream::ZCursor::new(b);
    patched::JpegDecoder::new(cursor)
        .decode()
        .map_err(|e| format!("{e:?}"))
}

/// SplitMix64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

fn damage(b: &mut Vec<u8>, rng: &mut Rng) {
    let kind = rng.next() % 5;
    for _ in 0..1 + rng.next() % 8 {
        let len = b.len();
        if len < 4 {
            return;
        }
        let pos = (rng.next() as usize) % len;
        match kind {
            0 => b[pos] ^= 1 << (rng.next() % 8),
            1 => b[pos] = 0xFF,
            2 => {
                b.insert(pos, 0xFF);
                b.insert(pos + 1, 0xD0 + (rng.next() % 8) as u8);
            }
            3 => b.truncate(pos.max(2)),
            _ => {
                b[pos] = 0xFF;
                if pos + 1 < len {
                    b[pos + 1] = 0;
                }
            }
        }
    }
}

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let Some(rounds) = args.next().and_then(|r| r.parse::<usize>().ok()) else {
        eprintln!("usage: zune-jpeg-differential ROUNDS FILE...");
        return ExitCode::from(2);
    };
    panic::set_hook(Box::new(|_| {}));
    let mut rng = Rng(42);
    let (mut same, mut differ) = (0usize, 0usize);
    for path in args {
        let original = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) => {
                eprintln!("{path}: {e}");
                return ExitCode::from(2);
            }
        };
        for round in 0..rounds.max(1) {
            let mut b = original.clone();
            if round > 0 {
                damage(&mut b, &mut rng);
            }
            let r = panic::catch_unwind(|| released(&b));
            let p = panic::catch_unwind(|| patched(&b));
            let agree = match (&r, &p) {
                (Ok(Ok(x)), Ok(Ok(y))) => x == y,
                (Ok(Err(_)), Ok(Err(_))) | (Err(_), Err(_)) => true,
                _ => false,
            };
            if agree {
                same += 1;
            } else {
                differ += 1;
                let out = format!("differs_{differ}.jpg");
                let _ = std::fs::write(&out, &b);
                let show = |v: &std::thread::Result<Result<Vec<u8>, String>>| match v {
                    Ok(Ok(px)) => format!("{} bytes", px.len()),
                    Ok(Err(e)) => format!("error {e}"),
                    Err(_) => "panic".to_string(),
                };
                eprintln!(
                    "{path}, damaged copy {round}: released {}, patched {} (written to {out})",
                    show(&r),
                    show(&p)
                );
            }
        }
    }
    println!("{same} decodes agree, {differ} differ");
    if differ > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}
