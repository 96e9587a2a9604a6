#!/usr/bin/env python3
"""How well response curves make a real bracket's neighbouring frames agree, pixel by pixel.

For each pair of neighbouring frames (j shorter, k longer) and each pixel whose codes in both
lie in 10..=230 (neither dark nor near the clip), the residual in stops

    r = [(g(z_j) - ln t_j) - (g(z_k) - ln t_k)] / ln 2

is zero for a curve that reads both frames as the same light. A curve is only known up to an
offset, which cancels here. Printed per curve and channel: the median |r| over all such pixels,
and the median r (the bias) in bands of the longer frame's code. A curve whose shape is off
by a wave that the bracket's steps can see shows as a bias of opposite sign in different bands.
No merge is involved, so curves from any tool compare alike (a skydome profile's `g`, or a
colour-hdri `.npy` per channel).

How to run (from the repository root; needs numpy and opencv-python-headless, as in
scripts/requirements.txt):

    skydome calibrate A.jpg B.jpg C.jpg --times 0.125,1,8 --method joined -o joined.json
    skydome calibrate A.jpg B.jpg C.jpg --times 0.125,1,8 --method robust -o robust.json
    python3 scripts/pair_consistency.py --times 0.125,1,8 A.jpg B.jpg C.jpg \
        --curve joined.json --curve robust.json [--curve NAME=g_0.npy,g_1.npy,g_2.npy] [--json]

Frames are given shortest first, with their times in seconds. The frames must be aligned
(a hand-held bracket's residuals measure its motion, not the curve). docs/accuracy.md,
"Fifteenth round", has the figures for frobisher_001 and banterle_room's sub-brackets.
"""
import argparse
import json
import os
import sys

import cv2
import numpy as np

LO, HI = 10, 230
BANDS = [(10, 60), (60, 120), (120, 170), (170, 200), (200, 231)]


def load_curve(spec):
    """(name, 3 x 256 array of g in natural log units) from `profile.json` or
    `NAME=c0.npy,c1.npy,c2.npy`."""
    if "=" in spec:
        name, files = spec.split("=", 1)
        g = np.array([np.load(f) for f in files.split(",")], dtype=float)
    else:
        name = os.path.splitext(os.path.basename(spec))[0]
        with open(spec) as f:
            g = np.array(json.load(f)["g"], dtype=float)
        if g.shape[0] != 3:
            g = g.T
    if g.shape != (3, 256):
        raise ValueError(f"{spec}: a curve needs 3 channels of 256 codes, got {g.shape}")
    return name, g


def residuals(frames, log_t, g):
    """Per channel: (all residuals in stops, the longer frame's codes)."""
    out = []
    for c in range(3):
        rs, zs = [], []
        for j in range(len(frames) - 1):
            zj, zk = frames[j][..., c], frames[j + 1][..., c]
            m = (zj >= LO) & (zj <= HI) & (zk >= LO) & (zk <= HI)
            a, b = zj[m], zk[m]
            rs.append(((g[c][a] - log_t[j]) - (g[c][b] - log_t[j + 1])) / np.log(2))
            zs.append(b)
        out.append((np.concatenate(rs), np.concatenate(zs)))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("frames", nargs="+", help="the bracket, shortest exposure first")
    p.add_argument("--times", required=True, help="exposure times in seconds, in frame order")
    p.add_argument("--curve", action="append", required=True, help="profile.json or NAME=c0.npy,c1.npy,c2.npy")
    p.add_argument("--json", action="store_true", help="one JSON object instead of a table")
    a = p.parse_args()
    times = [float(t) for t in a.times.split(",")]
    if len(times) != len(a.frames) or len(times) < 2:
        sys.exit(f"error: {len(a.frames)} frames but {len(times)} times (2 or more of each, in the same order)")
    if any(not t > 0 for t in times) or times != sorted(times):
        sys.exit("error: times must be positive and given shortest first, as the frames")
    frames = []
    for f in a.frames:
        img = cv2.imread(f, cv2.IMREAD_COLOR)
        if img is None:
            sys.exit(f"error: {f}: not an image OpenCV can read")
        if img.dtype != np.uint8:
            sys.exit(f"error: {f}: 8-bit frames only")
        frames.append(img[..., ::-1].astype(np.intp))
    if len({f.shape for f in frames}) != 1:
        sys.exit("error: the frames differ in size")
    log_t = np.log(times)
    result = {}
    for spec in a.curve:
        try:
            name, g = load_curve(spec)
        except (OSError, ValueError, KeyError) as e:
            sys.exit(f"error: {spec}: {e}")
        per = []
        for r, z in residuals(frames, log_t, g):
            bands = {}
            for lo, hi in BANDS:
                m = (z >= lo) & (z < hi)
                bands[f"{lo}-{hi - 1}"] = float(np.median(r[m])) if m.sum() >= 50 else None
            per.append({"median_abs_stops": float(np.median(np.abs(r))), "pixels": int(r.size), "bias_by_longer_code": bands})
        result[name] = per
    if a.json:
        print(json.dumps(result, indent=1))
        return
    print("curve: median |r| (stops) R G B | bias by the longer frame's code, R/G/B")
    for name, per in result.items():
        cells = []
        for lo, hi in BANDS:
            k = f"{lo}-{hi - 1}"
            v = ["  n/a " if ch["bias_by_longer_code"][k] is None else f"{ch['bias_by_longer_code'][k]:+.3f}" for ch in per]
            cells.append(f"{k}: {'/'.join(v)}")
        med = " ".join(f"{ch['median_abs_stops']:.4f}" for ch in per)
        print(f"{name}: {med} | {'  '.join(cells)}")


if __name__ == "__main__":
    main()
