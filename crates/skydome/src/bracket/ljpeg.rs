//! A lossless JPEG decoder (ITU-T T.81 process 14, `SOF3`: Huffman coding, predictors 1–7,
//! point transform, restart intervals of whole rows) for the streams `jpeg-decoder` 0.3 refuses:
//! those with two components, which the Adobe DNG Converter writes for Bayer tiles (two
//! photosites coded as one two-component pixel). Every read is bounds-checked; a malformed
//! stream gives an error, never a panic.

/// A decoded stream: `width × height` pixels of `components` interleaved samples each.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Lossless {
    /// Pixels per row (the frame header's X).
    pub width: usize,
    /// Rows (the frame header's Y).
    pub height: usize,
    /// Interleaved components per pixel (1–4).
    pub components: usize,
    /// The samples in raster order, components interleaved, already shifted back by the point
    /// transform; at most the `max_samples` asked for.
    pub samples: Vec<u16>,
}

/// The number of components in the stream's `SOF3` frame header, if it has one before its
/// first scan.
pub fn component_count(data: &[u8]) -> Option<usize> {
    let mut at = 2;
    if data.get(..2) != Some(&[0xFF, 0xD8]) {
        return None;
    }
    loop {
        let (m, seg) = next_segment(data, &mut at).ok()?;
        match m {
            0xC3 => return seg.get(5).map(|&n| usize::from(n)),
            0xDA | 0xD9 => return None,
            _ => {}
        }
    }
}

/// Reads the marker at `*at` (skipping fill bytes) and its segment; `*at` moves past it.
fn next_segment<'a>(data: &'a [u8], at: &mut usize) -> Result<(u8, &'a [u8]), String> {
    let mut i = *at;
    if data.get(i) != Some(&0xFF) {
        return Err("lossless JPEG: marker expected".into());
    }
    while data.get(i) == Some(&0xFF) {
        i += 1;
    }
    let m = *data.get(i).ok_or("lossless JPEG: ends inside a marker")?;
    i += 1;
    if m == 0xD9 || (0xD0..=0xD7).contains(&m) || m == 0x01 {
        *at = i;
        return Ok((m, &[]));
    }
    let len = match data.get(i..i + 2) {
        Some(b) => usize::from(u16::from_be_bytes([b[0], b[1]])),
        None => return Err("lossless JPEG: ends inside a segment length".into()),
    };
    if len < 2 {
        return Err("lossless JPEG: segment length below 2".into());
    }
    let seg = data
        .get(i + 2..i + len)
        .ok_or("lossless JPEG: segment longer than the stream")?;
    *at = i + len;
    Ok((m, seg))
}

/// A Huffman table as T.81 Annex F builds it: per code length, the largest code and where its
/// symbols start.
#[derive(Clone)]
struct Huffman {
    max_code: [i32; 17],
    val_ptr: [i32; 17],
    min_code: [i32; 17],
    symbols: Vec<u8>,
}

impl Huffman {
    fn new(counts: &[u8; 16], symbols: Vec<u8>) -> Self {
        let mut h = Huffman {
            max_code: [-1; 17],
            val_ptr: [0; 17],
            min_code: [0; 17],
            symbols,
        };
        let (mut code, mut k) = (0i32, 0i32);
        for len in 1..=16 {
            let n = i32::from(counts[len - 1]);
            if n > 0 {
                h.val_ptr[len] = k;
                h.min_code[len] = code;
                code += n;
                k += n;
                h.max_code[len] = code - 1;
            }
            code <<= 1;
        }
        h
    }
}

/// The entropy-coded bits after a scan header: `0xFF 0x00` is a data byte `0xFF`; any other
/// marker ends the data.
struct Bits<'a> {
    data: &'a [u8],
    at: usize,
    acc: u32,
    have: u32,
}

impl Bits<'_> {
    fn bit(&mut self) -> Result<u32, String> {
        if self.have == 0 {
            let b = *self
                .data
                .get(self.at)
                .ok_or("lossless JPEG: data ends early")?;
            if b == 0xFF {
                if self.data.get(self.at + 1) != Some(&0x00) {
                    return Err("lossless JPEG: data ends early (marker inside a scan)".into());
                }
                self.at += 1;
            }
            self.at += 1;
            self.acc = u32::from(b);
            self.have = 8;
        }
        self.have -= 1;
        Ok((self.acc >> self.have) & 1)
    }

    fn bits(&mut self, n: u32) -> Result<u32, String> {
        let mut v = 0;
        for _ in 0..n {
            v = (v << 1) | self.bit()?;
        }
        Ok(v)
    }

    fn decode(&mut self, h: &Huffman) -> Result<u32, String> {
        let mut code = 0i32;
        for len in 1..=16 {
            code = (code << 1) | self.bit()? as i32;
            if code <= h.max_code[len] {
                let k = (h.val_ptr[len] + code - h.min_code[len]) as usize;
                return h
                    .symbols
                    .get(k)
                    .map(|&s| u32::from(s))
                    .ok_or_else(|| "lossless JPEG: bad Huffman code".into());
            }
        }
        Err("lossless JPEG: bad Huffman code".into())
    }

    /// Skips to the next byte and past the restart marker expected there.
    fn restart(&mut self) -> Result<(), String> {
        self.have = 0;
        match self.data.get(self.at..self.at + 2) {
            Some([0xFF, m]) if (0xD0..=0xD7).contains(m) => {
                self.at += 2;
                Ok(())
            }
            _ => Err("lossless JPEG: restart marker expected".into()),
        }
    }
}

/// Decodes a lossless JPEG stream, keeping its first `max_samples` samples (the rest of the
/// stream is not decoded). Refuses other JPEG processes, subsampled components, arithmetic
/// coding and restart intervals that are not whole rows.
pub fn decode(data: &[u8], max_samples: usize) -> Result<Lossless, String> {
    if data.get(..2) != Some(&[0xFF, 0xD8]) {
        return Err("lossless JPEG: no start-of-image marker".into());
    }
    let mut at = 2;
    let mut frame: Option<(u32, usize, usize, Vec<u8>)> = None;
    let mut tables: [Option<Huffman>; 4] = [None, None, None, None];
    let mut restart = 0usize;
    loop {
        let (m, seg) = next_segment(data, &mut at)?;
        match m {
            0xC3 => {
                if seg.len() < 6 {
                    return Err("lossless JPEG: short frame header".into());
                }
                let p = u32::from(seg[0]);
                let h = usize::from(u16::from_be_bytes([seg[1], seg[2]]));
                let w = usize::from(u16::from_be_bytes([seg[3], seg[4]]));
                let nf = usize::from(seg[5]);
                if !(2..=16).contains(&p) || !(1..=4).contains(&nf) || w == 0 || h == 0 {
                    return Err(format!(
                        "lossless JPEG: unsupported frame ({p}-bit, {w} × {h}, {nf} components)"
                    ));
                }
                if seg.len() < 6 + 3 * nf {
                    return Err("lossless JPEG: short frame header".into());
                }
                let mut ids = Vec::with_capacity(nf);
                for c in 0..nf {
                    if seg[7 + 3 * c] != 0x11 {
                        return Err("lossless JPEG: subsampled components are not read".into());
                    }
                    ids.push(seg[6 + 3 * c]);
                }
                frame = Some((p, w, h, ids));
            }
            0xC0..=0xCF if m != 0xC4 && m != 0xC8 && m != 0xCC => {
                return Err("lossless JPEG: not a lossless Huffman frame (SOF3)".into());
            }
            0xC4 => {
                let mut s = seg;
                while !s.is_empty() {
                    if s.len() < 17 {
                        return Err("lossless JPEG: short Huffman table".into());
                    }
                    let (class, id) = (s[0] >> 4, usize::from(s[0] & 15));
                    let mut counts = [0u8; 16];
                    counts.copy_from_slice(&s[1..17]);
                    let n: usize = counts.iter().map(|&c| usize::from(c)).sum();
                    if class != 0 || id > 3 || n > 256 || s.len() < 17 + n {
                        return Err("lossless JPEG: bad Huffman table".into());
                    }
                    tables[id] = Some(Huffman::new(&counts, s[17..17 + n].to_vec()));
                    s = &s[17 + n..];
                }
            }
            0xDD => {
                let b = seg
                    .get(..2)
                    .ok_or("lossless JPEG: short restart interval")?;
                restart = usize::from(u16::from_be_bytes([b[0], b[1]]));
            }
            0xDA => {
                let (p, w, h, ids) = frame.ok_or("lossless JPEG: scan before the frame header")?;
                let nf = ids.len();
                let ns = usize::from(*seg.first().ok_or("lossless JPEG: short scan header")?);
                if ns != nf || seg.len() < 1 + 2 * ns + 3 {
                    return Err("lossless JPEG: only one scan with every component is read".into());
                }
                // The scan's tables, in the frame's component order.
                let mut huff = Vec::with_capacity(nf);
                for (c, id) in ids.iter().enumerate() {
                    if seg[1 + 2 * c] != *id {
                        return Err("lossless JPEG: scan components out of frame order".into());
                    }
                    let t = usize::from(seg[2 + 2 * c] >> 4);
                    huff.push(
                        tables
                            .get(t)
                            .and_then(|t| t.clone())
                            .ok_or("lossless JPEG: missing Huffman table")?,
                    );
                }
                let predictor = seg[1 + 2 * ns];
                let pt = u32::from(seg[3 + 2 * ns] & 15);
                if !(1..=7).contains(&predictor) || pt >= p {
                    return Err(format!(
                        "lossless JPEG: predictor {predictor}, point transform {pt} not read"
                    ));
                }
                if restart > 0 && !restart.is_multiple_of(w) {
                    return Err("lossless JPEG: restart interval is not whole rows".into());
                }
                let rows_per_interval = if restart > 0 { restart / w } else { h };
                let row_len = w * nf;
                let total = row_len
                    .checked_mul(h)
                    .ok_or("lossless JPEG: too large")?
                    .min(max_samples);
                // Every sample takes at least one bit: a stream cannot hold more than 8 per
                // byte, so a header announcing more does not allocate more.
                let mut out: Vec<i32> = Vec::with_capacity(total.min(8 * data.len()));
                let mut bits = Bits {
                    data,
                    at,
                    acc: 0,
                    have: 0,
                };
                let initial = 1i32 << (p - pt - 1);
                let mask = (1i32 << 16) - 1;
                'rows: for y in 0..h {
                    let first_row = y % rows_per_interval == 0;
                    if first_row && y > 0 {
                        bits.restart()?;
                    }
                    for x in 0..w {
                        for table in &huff {
                            if out.len() == total {
                                break 'rows;
                            }
                            let k = out.len();
                            let pred = if first_row {
                                if x == 0 {
                                    initial
                                } else {
                                    out[k - nf]
                                }
                            } else if x == 0 {
                                out[k - row_len]
                            } else {
                                let (ra, rb, rc) =
                                    (out[k - nf], out[k - row_len], out[k - row_len - nf]);
                                match predictor {
                                    1 => ra,
                                    2 => rb,
                                    3 => rc,
                                    4 => ra + rb - rc,
                                    5 => ra + ((rb - rc) >> 1),
                                    6 => rb + ((ra - rc) >> 1),
                                    _ => (ra + rb) >> 1,
                                }
                            };
                            let ssss = bits.decode(table)?;
                            let diff = match ssss {
                                0 => 0,
                                1..=15 => {
                                    let v = bits.bits(ssss)? as i32;
                                    if v < 1 << (ssss - 1) {
                                        v - (1 << ssss) + 1
                                    } else {
                                        v
                                    }
                                }
                                16 => 32768,
                                _ => return Err("lossless JPEG: bad difference category".into()),
                            };
                            out.push((pred + diff) & mask);
                        }
                    }
                }
                let samples = out.into_iter().map(|v| (v << pt) as u16).collect();
                return Ok(Lossless {
                    width: w,
                    height: h,
                    components: nf,
                    samples,
                });
            }
            0xD9 => return Err("lossless JPEG: no scan".into()),
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_headers_are_errors() {
        assert!(decode(&[], 10).is_err());
        assert!(decode(&[0xFF, 0xD8], 10).is_err());
        assert!(decode(&[0xFF, 0xD8, 0xFF, 0xC0, 0, 2], 10).is_err());
        assert!(decode(&[0xFF, 0xD8, 0xFF, 0xC3, 0, 1], 10).is_err());
        assert!(decode(&[0xFF, 0xD8, 0xFF, 0xDA, 0, 2], 10).is_err());
        assert_eq!(component_count(&[0xFF, 0xD8]), None);
    }
}
