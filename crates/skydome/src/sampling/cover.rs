//! The covering draw ([`SampleOptions::cover`]): samples spread over every code band of every
//! frame and channel, so the curve's ends — the darkest codes of the longest frame, the
//! brightest unclipped codes of the shortest — are held by data, not by smoothness alone.

use super::{Draws, Lattice};

/// A candidate's state in the covering draw.
#[derive(Clone, Copy, PartialEq, Eq)]
enum State {
    Untried,
    Taken,
    Refused,
}

impl Draws<'_> {
    /// The covering draw: the lattice's candidates are put into cells `(frame, channel, code
    /// band)` — [`SampleOptions::cover`] equal bands of `0..=255`, a candidate in every cell its
    /// patch means fall in (codes 0 and 255 say nothing about their frame and are not
    /// counted) — and the cells are visited in turn, each taking its next candidate that passes
    /// the rejections and is not taken yet, until `target` are kept or every cell runs dry. A
    /// candidate fills several cells at once (one per frame it reads in); a cell's turn is
    /// skipped while it already holds more samples than the round number, so sparse cells (the
    /// ends) catch up with the middle ones.
    pub(super) fn cover(&mut self, lat: &Lattice, target: usize) {
        let p = self.src.frames();
        let nb = self.opts.cover.clamp(1, 256);
        let ncell = p * 3 * nb;
        let cell_of = |j: usize, c: usize, z: f32| -> Option<usize> {
            (0.5..=254.5)
                .contains(&z)
                .then(|| (j * 3 + c) * nb + ((z / 256.0 * nb as f32) as usize).min(nb - 1))
        };
        let mut cells: Vec<Vec<usize>> = vec![Vec::new(); ncell];
        // In the lattice's random order, so each cell's list is random too.
        for &k in &lat.order {
            for (j, v) in lat.values(k, p).iter().enumerate() {
                for (c, &z) in v.iter().enumerate() {
                    if let Some(cell) = cell_of(j, c, z) {
                        cells[cell].push(k);
                    }
                }
            }
        }
        let mut count = vec![0usize; ncell];
        let mut next = vec![0usize; ncell];
        let mut state = vec![State::Untried; lat.cand.len()];
        let mut round = 0usize;
        while self.positions.len() < target {
            round += 1;
            let mut any = false;
            for cell in 0..ncell {
                if self.positions.len() >= target {
                    break;
                }
                if count[cell] >= round {
                    continue;
                }
                while next[cell] < cells[cell].len() {
                    let k = cells[cell][next[cell]];
                    next[cell] += 1;
                    any = true;
                    if state[k] != State::Untried {
                        continue;
                    }
                    let vals = lat.values(k, p);
                    let (x, y) = lat.cand[k];
                    if self.exclude.contains(&(x, y)) {
                        state[k] = State::Refused;
                        continue;
                    }
                    match self.refuses(vals, x, y) {
                        None => return,
                        Some(true) => {
                            state[k] = State::Refused;
                            continue;
                        }
                        Some(false) => {}
                    }
                    state[k] = State::Taken;
                    self.taken.insert((x, y));
                    self.positions.push((x, y));
                    self.values.extend_from_slice(vals);
                    for (j, v) in vals.iter().enumerate() {
                        for (c, &z) in v.iter().enumerate() {
                            if let Some(cl) = cell_of(j, c, z) {
                                count[cl] += 1;
                            }
                        }
                    }
                    break;
                }
            }
            if !any && (0..ncell).all(|c| next[c] >= cells[c].len()) {
                break; // every cell ran dry
            }
        }
    }
}
