#!/usr/bin/env python3
"""OpenCV's Debevec calibration and merge on every real bracket in ../shared/data: frame consistency.

How to run (from the repository root; needs numpy and opencv-python-headless):

    python3 -m venv target/cv-venv && target/cv-venv/bin/pip install numpy opencv-python-headless
    target/cv-venv/bin/python scripts/real_sets_opencv.py [--align] [DATA_DIR]   # default ../shared/data

For each set: `CalibrateDebevec()` and `MergeDebevec()` with OpenCV's defaults (70 samples,
lambda 10) on the frames as decoded RGB, then per frame the median over its well-exposed pixels
(all channels in 20..=235) of |log2(E_frame / E_merged)|, E_frame = crf(Z) / t from OpenCV's own
curve — the same measure as skydome's `frame_consistency` (crates/skydome/tests/common/mod.rs).
With `--align` the hand-held banterle_alignment is aligned first (`cv2.createAlignMTB`, as
OpenCV's HDR tutorial does; `OPENCV_ALIGNED_BANTERLE` in noise_merge.rs), the other sets as
without. Prints one JSON object: set -> per-frame list (shortest first). The numbers are pasted into
`OPENCV_FRAME_CONSISTENCY` in crates/skydome/tests/lib/noise_merge.rs and docs/accuracy.md.
"""
import json
import os
import sys

import cv2
import numpy as np

ROOM = [2.0, 0.5, 0.125, 1 / 30, 1 / 125, 1 / 1000, 1 / 4000]
SETS = {
    "frobisher_001": [(f"IMG_{i}.jpg", t) for i, t in zip(range(2600, 2603), [0.125, 1.0, 8.0])],
    # Times from EXIF (the files are not in exposure order).
    "banterle_alignment": [("IMG_4209.jpg", 1 / 80), ("IMG_4210.jpg", 1 / 320), ("IMG_4211.jpg", 1 / 20)],
    "banterle_room": [(f"stack_room_exp_{i}.jpg", ROOM[i]) for i in range(7)],
    # No published times; frames are documented as 1 stop apart (SOURCE.txt).
    "skycam_alpnach_fisheye": [
        (f"Alpnach_20180129_11-09-20_ExposureStack_Image_{i:02}_image.png", 2.0**i) for i in range(13)
    ],
    "ssarcandy_street": [(f"DSC_{i:04}.png", 2.0 ** (i - 102)) for i in range(92, 103)],
}


def consistency(frames, times, crf, merged):
    out = []
    for img, t in zip(frames, times):
        well = np.all((img >= 20) & (img <= 235), axis=2)
        d = []
        for c in range(3):
            ej = crf[img[..., c], c] / t
            em = merged[..., c]
            ok = well & (ej > 0) & (em > 0)
            d.append(np.abs(np.log2(ej[ok] / em[ok])))
        d = np.concatenate(d)
        out.append(float(np.median(d)) if d.size else float("nan"))
    return out


def main():
    args = [a for a in sys.argv[1:] if a != "--align"]
    align = len(args) < len(sys.argv) - 1
    data = args[0] if args else os.path.join("..", "shared", "data")
    result = {}
    for name, files in SETS.items():
        files = sorted(files, key=lambda f: f[1])
        rgb = []
        for f, _ in files:
            bgr = cv2.imread(os.path.join(data, name, f), cv2.IMREAD_COLOR)
            rgb.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        times = np.array([t for _, t in files], dtype=np.float32)
        if align and name == "banterle_alignment":
            aligned = [x.copy() for x in rgb]
            cv2.createAlignMTB().process(rgb, aligned)
            rgb = aligned
        crf = cv2.createCalibrateDebevec().process(rgb, times)[:, 0, :]
        merged = cv2.createMergeDebevec().process(rgb, times, crf[:, None, :].copy())
        result[name] = [round(v, 4) for v in consistency(rgb, times, crf, merged)]
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
