#![allow(dead_code)] // the fuzz seeds use `seeds`, the tests `specs`
//! Small DNGs in every layout `bracket::dng` reads, for the tests and the fuzzers' `read_dng`
//! corpus (`fuzz/examples/seeds.rs` includes this file): strips and
//! tiles, 8/16-bit and bit-packed 12/14-bit samples, lossless JPEG (one, two and three
//! components),
//! LinearRaw, a linearisation table, a 2 × 2 black-level pattern, an active area, the raw image
//! in a SubIFD, both byte orders. Written by hand (a few tags, one IFD or two) because the seeds
//! must reach every branch of the reader, which the `tiff` crate's writer does not produce.

/// One TIFF entry: tag, type, values (as bytes in the file's byte order, built by `Dng`).
struct Entry {
    tag: u16,
    kind: u16,
    count: u32,
    data: Vec<u8>,
}

/// How the samples are laid out.
#[derive(Clone, Copy)]
pub enum Layout {
    /// Uncompressed strips of `rows` rows.
    Strips { rows: usize },
    /// Uncompressed tiles.
    Tiles { w: usize, h: usize },
    /// Lossless JPEG tiles (compression 7).
    Ljpeg { w: usize, h: usize },
    /// Lossless JPEG tiles whose JPEG pixels hold two photosites each (a `w / 2 × h` image of
    /// two components), as the Adobe DNG Converter writes Bayer tiles.
    LjpegPairs { w: usize, h: usize },
}

/// A DNG to build.
pub struct Spec {
    pub width: usize,
    pub height: usize,
    /// 1 (CFA) or 3 (LinearRaw).
    pub spp: usize,
    pub bits: usize,
    pub layout: Layout,
    pub big_endian: bool,
    /// The raw image in a SubIFD of IFD0 (a preview in IFD0), as DNG converters write it.
    pub sub_ifd: bool,
    pub cfa: [u8; 4],
    pub black: Vec<u32>,
    /// BlackLevelRepeatDim (rows, cols) when `black` has more than one value per plane.
    pub black_dim: Option<(u16, u16)>,
    pub white: u32,
    pub linearization: Option<Vec<u16>>,
    /// ActiveArea: top, left, bottom, right.
    pub active_area: Option<[u32; 4]>,
    pub exif: bool,
}

impl Spec {
    pub fn cfa(width: usize, height: usize, bits: usize, layout: Layout) -> Self {
        Spec {
            width,
            height,
            spp: 1,
            bits,
            layout,
            big_endian: false,
            sub_ifd: false,
            cfa: [0, 1, 1, 2],
            black: vec![64],
            black_dim: None,
            white: (1 << bits) - 1,
            linearization: None,
            active_area: None,
            exif: true,
        }
    }
}

/// The sample of photosite `(x, y)`, plane `s`: a ramp with some texture, in range.
pub fn sample(spec: &Spec, x: usize, y: usize, s: usize) -> u16 {
    let max = (1u32 << spec.bits) - 1;
    let v = (x * 97 + y * 61 + s * 333 + (x * y) % 17 * 29) as u32 % (max + 1);
    v as u16
}

fn u16b(v: u16, big: bool) -> [u8; 2] {
    if big {
        v.to_be_bytes()
    } else {
        v.to_le_bytes()
    }
}
fn u32b(v: u32, big: bool) -> [u8; 4] {
    if big {
        v.to_be_bytes()
    } else {
        v.to_le_bytes()
    }
}

/// Bit-packs samples of one row, big-endian bit order, the row starting on a byte.
fn pack(samples: &[u16], bits: usize) -> Vec<u8> {
    let mut out = Vec::new();
    let (mut acc, mut have) = (0u64, 0usize);
    for &s in samples {
        acc = (acc << bits) | u64::from(s);
        have += bits;
        while have >= 8 {
            have -= 8;
            out.push((acc >> have) as u8);
        }
    }
    if have > 0 {
        out.push((acc << (8 - have)) as u8);
    }
    out
}

/// Uncompressed bytes of the chunk `(cx, cy, cw, ch)` (rows past the image are padding).
fn raw_chunk(spec: &Spec, cx: usize, cy: usize, cw: usize, ch: usize) -> Vec<u8> {
    let mut out = Vec::new();
    for y in cy..cy + ch {
        let row: Vec<u16> = (cx..cx + cw)
            .flat_map(|x| {
                (0..spec.spp).map(move |s| {
                    if x < spec.width && y < spec.height {
                        sample(spec, x, y, s)
                    } else {
                        0
                    }
                })
            })
            .collect();
        match spec.bits {
            8 => out.extend(row.iter().map(|&v| v as u8)),
            16 => row
                .iter()
                .for_each(|&v| out.extend_from_slice(&u16b(v, spec.big_endian))),
            b => out.extend(pack(&row, b)),
        }
    }
    out
}

/// A lossless JPEG (SOF3, predictor 1, one Huffman table whose 17 categories all have 5-bit
/// codes) of `comps` interleaved components, `w × h` pixels.
pub fn ljpeg(samples: &[u16], w: usize, h: usize, comps: usize, bits: usize) -> Vec<u8> {
    ljpeg_with(
        samples,
        w,
        h,
        comps,
        bits,
        Coding {
            predictor: 1,
            pt: 0,
            restart_rows: 0,
        },
    )
}

/// How [`ljpeg_with`] codes: predictor (1–7, T.81 table H.1), point transform `pt` (the samples
/// must be multiples of `2^pt`), and a restart marker after every `restart_rows` rows when that
/// is not 0.
#[derive(Clone, Copy)]
pub struct Coding {
    pub predictor: u8,
    pub pt: usize,
    pub restart_rows: usize,
}

/// As [`ljpeg`], coded as `coding` says.
pub fn ljpeg_with(
    samples: &[u16],
    w: usize,
    h: usize,
    comps: usize,
    bits: usize,
    coding: Coding,
) -> Vec<u8> {
    let Coding {
        predictor,
        pt,
        restart_rows,
    } = coding;
    let mut o = vec![0xFF, 0xD8];
    // SOF3.
    o.extend_from_slice(&[0xFF, 0xC3]);
    o.extend_from_slice(&((8 + 3 * comps) as u16).to_be_bytes());
    o.push(bits as u8);
    o.extend_from_slice(&(h as u16).to_be_bytes());
    o.extend_from_slice(&(w as u16).to_be_bytes());
    o.push(comps as u8);
    for c in 0..comps {
        o.extend_from_slice(&[c as u8 + 1, 0x11, 0]);
    }
    // DHT: class 0, id 0; 17 codes of length 5.
    o.extend_from_slice(&[0xFF, 0xC4]);
    o.extend_from_slice(&((2 + 1 + 16 + 17) as u16).to_be_bytes());
    o.push(0x00);
    let mut counts = [0u8; 16];
    counts[4] = 17;
    o.extend_from_slice(&counts);
    o.extend(0..17u8);
    if restart_rows > 0 {
        o.extend_from_slice(&[0xFF, 0xDD, 0, 4]);
        o.extend_from_slice(&((restart_rows * w) as u16).to_be_bytes());
    }
    // SOS.
    o.extend_from_slice(&[0xFF, 0xDA]);
    o.extend_from_slice(&((6 + 2 * comps) as u16).to_be_bytes());
    o.push(comps as u8);
    for c in 0..comps {
        o.extend_from_slice(&[c as u8 + 1, 0x00]);
    }
    o.extend_from_slice(&[predictor, 0, pt as u8]);
    // Entropy-coded data (0xFF bytes stuffed with 0x00).
    struct Bits {
        out: Vec<u8>,
        acc: u64,
        have: usize,
    }
    impl Bits {
        fn put(&mut self, v: u32, n: usize) {
            self.acc = (self.acc << n) | u64::from(v & ((1u32 << n) - 1));
            self.have += n;
            while self.have >= 8 {
                self.have -= 8;
                let b = (self.acc >> self.have) as u8;
                self.out.push(b);
                if b == 0xFF {
                    self.out.push(0);
                }
            }
        }
    }
    let mut bits_out = Bits {
        out: Vec::new(),
        acc: 0,
        have: 0,
    };
    let at = |x: usize, y: usize, c: usize| i32::from(samples[(y * w + x) * comps + c] >> pt);
    let pad = |b: &mut Bits| {
        if b.have > 0 {
            let n = 8 - b.have;
            b.put((1 << n) - 1, n);
        }
    };
    for y in 0..h {
        // The first row of the image or of a restart interval.
        let first = y == 0 || (restart_rows > 0 && y % restart_rows == 0);
        if y > 0 && first {
            pad(&mut bits_out);
            let k = (y / restart_rows - 1) % 8;
            bits_out.out.extend_from_slice(&[0xFF, 0xD0 + k as u8]);
        }
        for x in 0..w {
            for c in 0..comps {
                let pred = match (x, first) {
                    (0, true) => 1 << (bits - pt - 1),
                    (_, true) => at(x - 1, y, c),
                    (0, false) => at(0, y - 1, c),
                    _ => {
                        let (ra, rb, rc) = (at(x - 1, y, c), at(x, y - 1, c), at(x - 1, y - 1, c));
                        match predictor {
                            1 => ra,
                            2 => rb,
                            3 => rc,
                            4 => ra + rb - rc,
                            5 => ra + ((rb - rc) >> 1),
                            6 => rb + ((ra - rc) >> 1),
                            _ => (ra + rb) >> 1,
                        }
                    }
                };
                let mut d = (at(x, y, c) - pred) as i16 as i32;
                if d == -32768 {
                    d = 32768;
                }
                let cat = if d == 0 {
                    0
                } else {
                    32 - d.unsigned_abs().leading_zeros()
                } as usize;
                bits_out.put(cat as u32, 5);
                if cat > 0 && cat < 16 {
                    let extra = if d < 0 { d - 1 } else { d };
                    bits_out.put(extra as u32, cat);
                }
            }
        }
    }
    // Pad the last byte with ones.
    pad(&mut bits_out);
    let bitbuf = bits_out.out;
    o.extend(bitbuf);
    o.extend_from_slice(&[0xFF, 0xD9]);
    o
}

/// Builds the DNG.
pub fn dng(spec: &Spec) -> Vec<u8> {
    let big = spec.big_endian;
    let short = |tag: u16, v: &[u16]| Entry {
        tag,
        kind: 3,
        count: v.len() as u32,
        data: v.iter().flat_map(|&x| u16b(x, big)).collect(),
    };
    let long = |tag: u16, v: &[u32]| Entry {
        tag,
        kind: 4,
        count: v.len() as u32,
        data: v.iter().flat_map(|&x| u32b(x, big)).collect(),
    };
    let srational = |tag: u16, v: &[(i32, i32)]| Entry {
        tag,
        kind: 10,
        count: v.len() as u32,
        data: v
            .iter()
            .flat_map(|&(n, d)| [u32b(n as u32, big), u32b(d as u32, big)].concat())
            .collect(),
    };
    let rational = |tag: u16, v: &[(u32, u32)]| Entry {
        tag,
        kind: 5,
        count: v.len() as u32,
        data: v
            .iter()
            .flat_map(|&(n, d)| [u32b(n, big), u32b(d, big)].concat())
            .collect(),
    };
    let bytes_entry = |tag: u16, kind: u16, v: &[u8]| Entry {
        tag,
        kind,
        count: v.len() as u32,
        data: v.to_vec(),
    };

    // The chunks.
    let (cw, ch, compression) = match spec.layout {
        Layout::Strips { rows } => (spec.width, rows, 1u16),
        Layout::Tiles { w, h } => (w, h, 1),
        Layout::Ljpeg { w, h } | Layout::LjpegPairs { w, h } => (w, h, 7),
    };
    let across = spec.width.div_ceil(cw);
    let down = spec.height.div_ceil(ch);
    let mut chunks = Vec::new();
    for i in 0..across * down {
        let (cx, cy) = ((i % across) * cw, (i / across) * ch);
        let rows = match spec.layout {
            Layout::Strips { .. } => ch.min(spec.height - cy),
            _ => ch,
        };
        chunks.push(match spec.layout {
            Layout::Ljpeg { .. } | Layout::LjpegPairs { .. } => {
                let s: Vec<u16> = (0..rows)
                    .flat_map(|y| {
                        (0..cw).flat_map(move |x| {
                            (0..spec.spp).map(move |s| {
                                let (xx, yy) = (cx + x, cy + y);
                                if xx < spec.width && yy < spec.height {
                                    sample(spec, xx, yy, s)
                                } else {
                                    0
                                }
                            })
                        })
                    })
                    .collect();
                match spec.layout {
                    Layout::LjpegPairs { .. } => ljpeg(&s, cw / 2, rows, 2, spec.bits),
                    _ => ljpeg(&s, cw, rows, spec.spp, spec.bits),
                }
            }
            _ => raw_chunk(spec, cx, cy, cw, rows),
        });
    }

    let mut raw = vec![
        long(254, &[0]),
        long(256, &[spec.width as u32]),
        long(257, &[spec.height as u32]),
        short(258, &vec![spec.bits as u16; spec.spp]),
        short(259, &[compression]),
        short(262, &[if spec.spp == 1 { 32803 } else { 34892 }]),
        short(277, &[spec.spp as u16]),
        long(50717, &[spec.white]),
    ];
    if spec.spp == 1 {
        raw.push(short(33421, &[2, 2]));
        raw.push(bytes_entry(33422, 1, &spec.cfa));
    }
    raw.push(long(50714, &spec.black));
    if let Some((r, c)) = spec.black_dim {
        raw.push(short(50713, &[r, c]));
    }
    if let Some(t) = &spec.linearization {
        raw.push(short(50712, t));
    }
    if let Some(a) = spec.active_area {
        raw.push(long(50829, &a));
    }
    // Chunk offsets are patched in once the layout is known: placeholders now.
    let n = chunks.len();
    let (off_tag, len_tag) = match spec.layout {
        Layout::Strips { rows } => {
            raw.push(long(278, &[rows as u32]));
            (273, 279)
        }
        _ => {
            raw.push(long(322, &[cw as u32]));
            raw.push(long(323, &[ch as u32]));
            (324, 325)
        }
    };
    raw.push(long(off_tag, &vec![0; n]));
    raw.push(long(
        len_tag,
        &chunks.iter().map(|c| c.len() as u32).collect::<Vec<_>>(),
    ));

    let mut root = vec![
        bytes_entry(50706, 1, &[1, 4, 0, 0]),
        bytes_entry(271, 2, b"skydome\0"),
        bytes_entry(272, 2, b"fuzz seed\0"),
        srational(
            50721,
            &[
                (9000, 10000),
                (-3000, 10000),
                (-1000, 10000),
                (-4000, 10000),
                (12000, 10000),
                (2000, 10000),
                (-500, 10000),
                (1500, 10000),
                (6000, 10000),
            ],
        ),
        short(50778, &[21]),
        rational(50728, &[(5, 10), (1, 1), (7, 10)]),
    ];
    if spec.exif {
        // An EXIF IFD with exposure time, f-number and ISO (patched below).
        root.push(long(34665, &[0]));
    }
    let exif_entries = vec![
        rational(33434, &[(1, 250)]),
        rational(33437, &[(18, 10)]),
        short(34855, &[100]),
    ];
    if spec.sub_ifd {
        root.push(long(330, &[0]));
        // IFD0 is then a tiny preview.
        root.push(long(254, &[1]));
    } else {
        root.extend(raw.drain(..).filter(|e| e.tag != 254));
        root.push(long(254, &[0]));
    }

    // Layout: header, IFD0 (+ its data), SubIFD, EXIF IFD, chunks.
    let mut out = Vec::new();
    out.extend_from_slice(if big { b"MM\0*" } else { b"II*\0" });
    out.extend_from_slice(&u32b(8, big));
    let ifd_size = |e: &[Entry]| {
        2 + 12 * e.len()
            + 4
            + e.iter()
                .map(|e| {
                    if e.data.len() > 4 {
                        e.data.len() + (e.data.len() & 1)
                    } else {
                        0
                    }
                })
                .sum::<usize>()
    };
    let root_at = 8;
    let sub_at = root_at + ifd_size(&root);
    let exif_at = sub_at + if spec.sub_ifd { ifd_size(&raw) } else { 0 };
    let data_at = exif_at
        + if spec.exif {
            ifd_size(&exif_entries)
        } else {
            0
        };
    let mut chunk_offsets = Vec::new();
    let mut at = data_at;
    for c in &chunks {
        chunk_offsets.push(at as u32);
        at += c.len() + (c.len() & 1);
    }
    let patch = |entries: &mut Vec<Entry>| {
        for e in entries.iter_mut() {
            match e.tag {
                t if t == off_tag => {
                    e.data = chunk_offsets.iter().flat_map(|&o| u32b(o, big)).collect()
                }
                330 => e.data = u32b(sub_at as u32, big).to_vec(),
                34665 => e.data = u32b(exif_at as u32, big).to_vec(),
                _ => {}
            }
        }
        entries.sort_by_key(|e| e.tag);
    };
    let write_ifd = |out: &mut Vec<u8>, entries: &[Entry]| {
        let start = out.len();
        let mut extra_at = start + 2 + 12 * entries.len() + 4;
        let mut extra = Vec::new();
        out.extend_from_slice(&u16b(entries.len() as u16, big));
        for e in entries {
            out.extend_from_slice(&u16b(e.tag, big));
            out.extend_from_slice(&u16b(e.kind, big));
            out.extend_from_slice(&u32b(e.count, big));
            if e.data.len() <= 4 {
                let mut v = e.data.clone();
                v.resize(4, 0);
                out.extend_from_slice(&v);
            } else {
                out.extend_from_slice(&u32b(extra_at as u32, big));
                extra.extend_from_slice(&e.data);
                if e.data.len() & 1 == 1 {
                    extra.push(0);
                }
                extra_at += e.data.len() + (e.data.len() & 1);
            }
        }
        out.extend_from_slice(&u32b(0, big));
        out.extend(extra);
    };
    let (mut root, mut raw, mut exif_entries) = (root, raw, exif_entries);
    patch(&mut root);
    patch(&mut raw);
    patch(&mut exif_entries);
    write_ifd(&mut out, &root);
    if spec.sub_ifd {
        write_ifd(&mut out, &raw);
    }
    if spec.exif {
        write_ifd(&mut out, &exif_entries);
    }
    assert_eq!(out.len(), data_at);
    for c in &chunks {
        out.extend_from_slice(c);
        if c.len() & 1 == 1 {
            out.push(0);
        }
    }
    out
}

/// The seeds: `(name, bytes)`.
pub fn seeds() -> Vec<(String, Vec<u8>)> {
    specs()
        .into_iter()
        .map(|(name, spec)| (name.to_string(), dng(&spec)))
        .collect()
}

/// The DNGs of [`seeds`] as specifications, `(name, spec)`.
pub fn specs() -> Vec<(&'static str, Spec)> {
    let mut v = Vec::new();
    let mut add = |name: &'static str, spec: Spec| v.push((name, spec));
    add(
        "strips16",
        Spec::cfa(16, 12, 16, Layout::Strips { rows: 5 }),
    );
    add("strips8", Spec::cfa(16, 12, 8, Layout::Strips { rows: 12 }));
    add(
        "packed12",
        Spec::cfa(18, 10, 12, Layout::Strips { rows: 4 }),
    );
    add(
        "packed14",
        Spec::cfa(14, 10, 14, Layout::Strips { rows: 10 }),
    );
    add(
        "tiles16",
        Spec::cfa(20, 14, 16, Layout::Tiles { w: 16, h: 16 }),
    );
    add(
        "ljpeg14",
        Spec::cfa(20, 12, 14, Layout::Ljpeg { w: 16, h: 8 }),
    );
    add(
        "ljpeg16",
        Spec::cfa(16, 16, 16, Layout::Ljpeg { w: 16, h: 16 }),
    );
    add(
        "linear_raw_ljpeg",
        Spec {
            spp: 3,
            ..Spec::cfa(12, 8, 12, Layout::Ljpeg { w: 12, h: 8 })
        },
    );
    add(
        "linear_raw_strips",
        Spec {
            spp: 3,
            ..Spec::cfa(12, 8, 16, Layout::Strips { rows: 3 })
        },
    );
    add(
        "big_endian_subifd",
        Spec {
            big_endian: true,
            sub_ifd: true,
            cfa: [1, 0, 2, 1],
            ..Spec::cfa(16, 12, 16, Layout::Strips { rows: 6 })
        },
    );
    add(
        "levels_area_lut",
        Spec {
            black: vec![60, 64, 66, 62],
            black_dim: Some((2, 2)),
            linearization: Some((0..4096).map(|i: u32| ((i * i) >> 8) as u16).collect()),
            white: 65000,
            active_area: Some([2, 2, 12, 16]),
            ..Spec::cfa(18, 14, 12, Layout::Strips { rows: 14 })
        },
    );
    add(
        "ljpeg_pairs14",
        Spec {
            sub_ifd: true,
            ..Spec::cfa(20, 12, 14, Layout::LjpegPairs { w: 16, h: 8 })
        },
    );
    add(
        "no_exif_subifd_ljpeg",
        Spec {
            exif: false,
            sub_ifd: true,
            ..Spec::cfa(16, 8, 12, Layout::Ljpeg { w: 8, h: 8 })
        },
    );
    v
}
