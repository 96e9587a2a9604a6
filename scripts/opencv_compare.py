#!/usr/bin/env python3
"""OpenCV's Debevec calibration and merge next to skydome's, on one synthetic bracket.

How to run (from the repository root):

    python3 -m venv /tmp/venv-cv && /tmp/venv-cv/bin/pip install numpy opencv-python-headless
    cargo run -p skydome --example synth_bracket -- /tmp/synth            # frames, truth, ours
    /tmp/venv-cv/bin/python scripts/opencv_compare.py /tmp/synth [--samples N]

The example writes the frames (PNG, the exact pixels skydome saw), `times.txt`, the true
radiance `truth.pfm`, the true curves `true_curves.csv`, skydome's merge `skydome_merged.pfm`
and curves `skydome_curves.csv`. This script runs OpenCV's CalibrateDebevec (same sample count
and lambda as skydome used — override with `--samples N` / `--lambda L` — and OpenCV's default
grid sampling) and MergeDebevec on the same PNGs,
then prints, for OpenCV, OpenCV's merge with skydome's curve, and skydome:

- curve RMSE in stops: RMS over z = 10..245 of (g_rec - g_true) / ln 2 after removing the mean;
- merge metrics against the truth over pixels well exposed (all channels in 10..245) in at
  least one frame, after fitting one scale per channel in the log domain (as skydome's
  `compare` with `per_channel_scale`): median and 95th-percentile relative error, log2 RMSE.

`--json` prints the numbers as JSON instead of a table. `--zmin Z` starts the curve comparison
at code Z instead of 10 (for a bracket with a black level b, where g below b is undefined: b + 4).
"""
import json
import os
import sys

import cv2
import numpy as np


def read_pfm(path):
    with open(path, "rb") as f:
        assert f.readline().strip() == b"PF"
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    return data.reshape(h, w, 3)[::-1].astype(np.float64)  # PFM is bottom row first


def read_curves(path):
    return np.loadtxt(path, delimiter=",", skiprows=1)[:, 1:4]


ZMIN = 10


def curve_rmse_stops(g, g_true):
    d = g[ZMIN:246] - g_true[ZMIN:246]
    d = d - d.mean(axis=0)
    return list(np.sqrt((d ** 2).mean(axis=0)) / np.log(2))


def merge_metrics(rad, truth, mask):
    ok = mask & np.all(np.isfinite(rad) & (rad > 0) & (truth > 0), axis=2)
    a, b = rad[ok], truth[ok]
    s = np.exp(np.mean(np.log(b) - np.log(a), axis=0))
    a = a * s
    rel = np.abs(a - b) / b
    return {
        "pixels": int(ok.sum()),
        "median_rel_error": float(np.median(rel)),
        "p95_rel_error": float(np.percentile(rel, 95)),
        "log2_rmse": float(np.sqrt(np.mean(np.log2(a / b) ** 2))),
    }


def main():
    args = sys.argv[1:]
    as_json = "--json" in args
    args = [a for a in args if a != "--json"]
    samples = None
    lam_arg = None
    if "--lambda" in args:
        i = args.index("--lambda")
        lam_arg = float(args[i + 1])
        del args[i : i + 2]
    if "--zmin" in args:
        # Lowest code of the curve comparison (default 10); above a black level b, use b + 4.
        global ZMIN
        i = args.index("--zmin")
        ZMIN = int(args[i + 1])
        del args[i : i + 2]
    if "--samples" in args:
        i = args.index("--samples")
        samples = int(args[i + 1])
        del args[i : i + 2]
    d = args[0]
    entries = [l.split() for l in open(os.path.join(d, "times.txt")) if l.strip()]
    imgs = [cv2.imread(os.path.join(d, n), cv2.IMREAD_COLOR) for n, _ in entries]
    times = np.array([float(t) for _, t in entries], dtype=np.float32)
    truth = read_pfm(os.path.join(d, "truth.pfm"))
    g_true = read_curves(os.path.join(d, "true_curves.csv"))
    ours_g = read_curves(os.path.join(d, "skydome_curves.csv"))
    ours = read_pfm(os.path.join(d, "skydome_merged.pfm"))
    rep = json.load(open(os.path.join(d, "skydome_report.json")))
    if samples is None:
        samples = rep["sampling"]["used"]

    rgb = [im[:, :, ::-1] for im in imgs]
    mask = np.zeros(truth.shape[:2], bool)
    for im in rgb:
        mask |= np.all((im >= 10) & (im <= 245), axis=2)

    lam = float(rep.get("lambda", 10.0)) if lam_arg is None else lam_arg
    cal = cv2.createCalibrateDebevec(samples, lam)
    resp = cal.process(imgs, times)  # 256x1x3, BGR, linear exposure
    g_cv = np.log(np.maximum(resp[:, 0, ::-1].astype(np.float64), 1e-30))
    hdr_cv = cv2.createMergeDebevec().process(imgs, times, resp)[:, :, ::-1].astype(np.float64)
    ours_resp = np.exp(ours_g[:, ::-1]).astype(np.float32).reshape(256, 1, 3)
    hdr_cv_ours = cv2.createMergeDebevec().process(imgs, times, ours_resp)[:, :, ::-1].astype(np.float64)

    true_resp = np.exp(g_true[:, ::-1]).astype(np.float32).reshape(256, 1, 3)
    hdr_cv_true = cv2.createMergeDebevec().process(imgs, times, true_resp)[:, :, ::-1].astype(np.float64)

    out = {
        "samples": samples,
        "lambda": lam,
        "opencv": {"curve_rmse_stops": curve_rmse_stops(g_cv, g_true), **merge_metrics(hdr_cv, truth, mask)},
        "opencv_merge_with_skydome_curve": merge_metrics(hdr_cv_ours, truth, mask),
        "opencv_merge_with_true_curve": merge_metrics(hdr_cv_true, truth, mask),
        "skydome": {"curve_rmse_stops": curve_rmse_stops(ours_g, g_true), **merge_metrics(ours, truth, mask)},
    }
    if as_json:
        print(json.dumps(out, indent=2))
        return
    print(f"OpenCV {cv2.__version__}, lambda {lam}, {samples} samples, {len(imgs)} frames, {out['skydome']['pixels']} pixels")
    print(f"{'':34} {'curve RMSE R/G/B (stops)':>28} {'median rel':>10} {'p95 rel':>8} {'log2 RMSE':>9}")
    for name, key in [("OpenCV Calibrate+MergeDebevec", "opencv"),
                      ("OpenCV merge, skydome curve", "opencv_merge_with_skydome_curve"),
                      ("OpenCV merge, true curve", "opencv_merge_with_true_curve"),
                      ("skydome", "skydome")]:
        r = out[key]
        c = "/".join(f"{v:.3f}" for v in r["curve_rmse_stops"]) if "curve_rmse_stops" in r else "-"
        print(f"{name:34} {c:>28} {r['median_rel_error']:>10.4f} {r['p95_rel_error']:>8.4f} {r['log2_rmse']:>9.4f}")


if __name__ == "__main__":
    main()
