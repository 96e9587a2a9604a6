#!/usr/bin/env python3
"""The two competitors `scripts/bench.sh` times against `skydome merge`, one process per run.

    bench_helper.py decode FRAME...                 # the decode floor
    bench_helper.py opencv OUTDIR TIMES FRAME...    # OpenCV's equivalent pipeline

`decode` decodes every JPEG to RGB pixels with Pillow (libjpeg-turbo, one thread) and nothing
else: no merge can take less than this, so skydome's time divided by it is how close the whole
job is to the cost of reading the photos.

`opencv` does what `skydome merge FRAMES -o s.hdr --preview s.png` does, with OpenCV's photo
module: `cv2.imread` of each frame, `CalibrateDebevec` (100 samples, OpenCV's default λ = 10),
`MergeDebevec`, `cv2.imwrite` of the Radiance `.hdr`, `TonemapReinhard` (OpenCV's defaults) and
`cv2.imwrite` of the 8-bit PNG preview. TIMES is a comma-separated list of exposure times in
seconds, in FRAME order.

Both print the wall time of their own work (after Python's start-up) on stderr; bench.sh times
the whole process and reads its peak memory itself.
"""
import os
import sys
import time


def decode(frames):
    from PIL import Image

    t0 = time.perf_counter()
    total = 0
    for f in frames:
        with Image.open(f) as im:
            im.draft(None, None)  # full resolution, no DCT scaling
            px = im.convert("RGB").tobytes()
            total += len(px)
    print(f"decode: {total / 3e6:.1f} MP in {time.perf_counter() - t0:.3f} s", file=sys.stderr)


def opencv(outdir, times, frames):
    import cv2
    import numpy as np

    cv2.setNumThreads(os.cpu_count() or 1)
    t0 = time.perf_counter()
    imgs = [cv2.imread(f, cv2.IMREAD_COLOR) for f in frames]
    if any(i is None for i in imgs):
        sys.exit("opencv: cannot read a frame")
    t = np.array([float(v) for v in times.split(",")], dtype=np.float32)
    response = cv2.createCalibrateDebevec(samples=100).process(imgs, t)
    hdr = cv2.createMergeDebevec().process(imgs, t, response)
    cv2.imwrite(os.path.join(outdir, "opencv.hdr"), hdr)
    ldr = cv2.createTonemapReinhard().process(hdr)
    cv2.imwrite(os.path.join(outdir, "opencv.png"), np.clip(ldr * 255, 0, 255).astype(np.uint8))
    print(f"opencv: {time.perf_counter() - t0:.3f} s", file=sys.stderr)


def main(argv):
    if len(argv) >= 2 and argv[0] == "decode":
        decode(argv[1:])
    elif len(argv) >= 4 and argv[0] == "opencv":
        opencv(argv[1], argv[2], argv[3:])
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main(sys.argv[1:])
