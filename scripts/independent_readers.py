#!/usr/bin/env python3
"""Check skydome's .hdr and .exr output with two independent readers: OpenCV and OpenImageIO.

Requirements (tested with numpy 2.4.6, opencv-python-headless 4.14.0.94, OpenImageIO 3.2.2.0):

    python3 -m venv /tmp/venv-formats
    /tmp/venv-formats/bin/pip install numpy "opencv-python-headless<5" OpenImageIO

(the opencv-python-headless 5.0.0.93 wheel is built without OpenEXR: it cannot read .exr).

Usage:

    independent_readers.py DIR
        Verify a directory written by crates/skydome/tests/lib/independent_readers.rs: DIR/manifest.json
        lists cases; each file is read with OpenCV (cv2.imread(path, cv2.IMREAD_UNCHANGED), BGR)
        and OpenImageIO and compared with the raw little-endian float32 RGB dump of what the file
        must hold (.hdr: our own decode, i.e. the RGBE-quantised values; .exr: the stored
        half/float values). Tolerances: .hdr 1e-6 relative (a reader decoding at the RGBE bin
        centre is accepted within one RGBE step and reported); half .exr 2^-11 relative;
        float .exr 1e-7 relative. Also checks that OpenImageIO sees the header attributes
        (sun, north, capture date, software) where it exposes them.

    independent_readers.py --check FILE [FILE ...]
        For real CLI outputs: open every .hdr/.exr with both readers, check that they agree with
        each other, and compare each .exr with a sibling .hdr of the same stem (out.exr ~ out.hdr)
        within RGBE precision (max channel / 256 plus half precision).

Exit status 0 when everything matches, 1 on any mismatch (each printed on one line), 2 on usage
errors or missing modules.
"""

import json
import os
import sys

# OpenCV refuses to decode EXR unless this is set before the module is imported.
os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")

try:
    import numpy as np
    import cv2
    import OpenImageIO as oiio
except ImportError as e:  # pragma: no cover - reported to the caller
    print(f"missing module: {e}; pip install numpy \"opencv-python-headless<5\" OpenImageIO", file=sys.stderr)
    sys.exit(2)

FAILURES = []


def fail(msg):
    FAILURES.append(msg)
    print(f"FAIL {msg}")


def read_cv2(path):
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise RuntimeError("OpenCV could not read it")
    img = np.asarray(img, dtype=np.float32)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    return img[:, :, 2::-1] if img.shape[2] >= 3 else img  # BGR(A) -> RGB


def read_oiio(path):
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise RuntimeError(f"OpenImageIO could not open it: {oiio.geterror()}")
    try:
        spec = inp.spec()
        px = inp.read_image(0, 0, 0, spec.nchannels, "float")
        if px is None:
            raise RuntimeError(f"OpenImageIO could not read pixels: {inp.geterror()}")
        px = np.asarray(px, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
        attrs = {a.name: a.value for a in spec.extra_attribs}
        return px[:, :, :3], attrs
    finally:
        inp.close()


def compare(label, got, want, rel, hdr_step=False):
    """Max relative error; fails when beyond `rel` (or, for .hdr, beyond one RGBE step)."""
    if got.shape != want.shape:
        fail(f"{label}: shape {got.shape} != expected {want.shape}")
        return
    finite = np.isfinite(want)
    if not np.array_equal(np.isnan(got), np.isnan(want)):
        fail(f"{label}: NaN positions differ")
        return
    g, w = got[finite].astype(np.float64), want[finite].astype(np.float64)
    err = np.abs(g - w)
    scale = np.maximum(np.abs(w), 1e-30)
    worst = float(np.max(err / scale)) if err.size else 0.0
    if np.all(err <= rel * np.abs(w)):
        print(f"ok   {label}: max relative error {worst:.2e}")
        return
    if hdr_step:
        # One RGBE step is (max channel of the pixel) / 128 at worst.
        pmax = np.max(np.abs(want), axis=2, keepdims=True).repeat(3, axis=2)[finite]
        if np.all(err <= pmax / 128.0 + 1e-30):
            print(f"ok   {label}: within one RGBE step (reader decodes at the bin centre), max rel {worst:.2e}")
            return
    bad = int(np.sum(err > rel * np.abs(w)))
    i = int(np.argmax(err / scale))
    fail(f"{label}: {bad} samples beyond tolerance {rel:g}; worst {g[i]!r} vs expected {w[i]!r}")


def check_manifest(directory):
    with open(os.path.join(directory, "manifest.json")) as f:
        manifest = json.load(f)
    for case in manifest["cases"]:
        h, w = case["height"], case["width"]
        for entry in case["files"]:
            path = os.path.join(directory, entry["file"])
            want = np.fromfile(os.path.join(directory, entry["expect"]), dtype="<f4").reshape(h, w, 3)
            kind = entry["kind"]
            rel = {"hdr": 1e-6, "half": 2.0 ** -11, "float": 1e-7}[kind]
            try:
                compare(f"{entry['file']} [OpenCV]", read_cv2(path), want, rel, kind == "hdr")
            except RuntimeError as e:
                fail(f"{entry['file']} [OpenCV]: {e}")
            try:
                px, attrs = read_oiio(path)
                compare(f"{entry['file']} [OpenImageIO]", px, want, rel, kind == "hdr")
                check_attrs(entry["file"], kind, attrs, case.get("attrs", {}))
            except RuntimeError as e:
                fail(f"{entry['file']} [OpenImageIO]: {e}")


def check_attrs(name, kind, attrs, expected):
    """OpenImageIO exposes EXR string attributes by name (capDate as DateTime, comments as
    ImageDescription); its .hdr reader exposes no header comment lines, so only EXR is checked."""
    if kind == "hdr":
        # OpenImageIO's .hdr reader only exposes EXPOSURE= (as hdr:exposure).
        want = expected.get("exposure")
        got = attrs.get("hdr:exposure")
        if want is not None and (got is None or abs(got - want) > 1e-6 * want):
            fail(f"{name} [OpenImageIO attributes]: hdr:exposure = {got!r}, expected {want!r}")
        else:
            print(f"ok   {name} [OpenImageIO attributes]: hdr:exposure = {got!r}")
        return
    wanted = {
        "skydome:sun": expected.get("sun"),
        "skydome:north": expected.get("north"),
        "DateTime": expected.get("capdate"),
        "software": expected.get("software"),
        "ImageDescription": expected.get("comments"),
    }
    bad = False
    for key, value in wanted.items():
        if value is None:
            continue
        got = attrs.get(key)
        if got != value:
            bad = True
            fail(f"{name} [OpenImageIO attributes]: {key} = {got!r}, expected {value!r} (OpenImageIO has {sorted(attrs)})")
    if not bad:
        print(f"ok   {name} [OpenImageIO attributes]: {', '.join(k for k, v in wanted.items() if v)}")


def check_files(paths):
    decoded = {}
    for path in paths:
        try:
            a = read_cv2(path)
            b, _ = read_oiio(path)
        except RuntimeError as e:
            fail(f"{path}: {e}")
            continue
        rel = 1e-6 if path.lower().endswith(".hdr") else 2.0 ** -11
        compare(f"{path} [OpenCV vs OpenImageIO]", a, b, rel, path.lower().endswith(".hdr"))
        decoded[path] = b
    for path, px in decoded.items():
        if not path.lower().endswith(".exr"):
            continue
        sibling = os.path.splitext(path)[0] + ".hdr"
        if not os.path.exists(sibling):
            continue
        ref = decoded.get(sibling)
        if ref is None:
            try:
                ref, _ = read_oiio(sibling)
            except RuntimeError as e:
                fail(f"{sibling}: {e}")
                continue
        if ref.shape != px.shape:
            fail(f"{path} vs {sibling}: shapes {px.shape} and {ref.shape} differ")
            continue
        ok = np.isfinite(px)
        pmax = np.max(np.where(np.isfinite(px), np.abs(px), 0), axis=2, keepdims=True).repeat(3, axis=2)
        tol = pmax / 256.0 + np.abs(px) * 2.0 ** -10 + 1e-30
        err = np.abs(px.astype(np.float64) - ref)
        bad = int(np.sum((err > tol) & ok))
        if bad:
            fail(f"{path} vs {sibling}: {bad} samples differ by more than RGBE precision")
        else:
            print(f"ok   {path} vs {sibling}: agree within RGBE precision")


def main(argv):
    if len(argv) >= 2 and argv[0] == "--check":
        check_files(argv[1:])
    elif len(argv) == 1 and os.path.isdir(argv[0]):
        check_manifest(argv[0])
    else:
        print(__doc__, file=sys.stderr)
        return 2
    if FAILURES:
        print(f"{len(FAILURES)} mismatch(es)", file=sys.stderr)
        return 1
    print("all independent reader checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
