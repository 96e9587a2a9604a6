"""The package's surface: names, signatures, docstrings and stubs."""

import inspect
from pathlib import Path

import skydome


def test_public_names():
    for name in ("run", "calibrate", "read_hdr", "write_hdr", "tonemap", "Dome",
                 "CameraProfile", "Error"):
        assert hasattr(skydome, name), name
    assert skydome.__version__


def test_run_signature_is_the_issue_s():
    sig = inspect.signature(skydome.run)
    assert list(sig.parameters) == [
        "frames", "times", "profile", "lens", "fisheye", "lens_model", "fov", "crop", "sun",
        "north", "time", "lat", "lon", "illuminance", "luminance", "weighting", "exposures",
        "preview", "equirect", "progress", "circle",
    ]
    p = sig.parameters
    assert p["sun"].default == "auto" and p["weighting"].default == "noise"
    assert p["exposures"].default == "listed"
    assert p["fisheye"].default is False and p["times"].default is None
    assert all(p[n].kind == inspect.Parameter.KEYWORD_ONLY for n in list(p)[2:])


def test_help_is_useful():
    doc = skydome.run.__doc__
    for words in ("frames", "times", "seconds", "degrees from true north towards east",
                  "progress(stage, fraction)", "KeyboardInterrupt", "skydome.Error"):
        assert words in doc, words
    assert "radiance" in skydome.Dome.radiance.__doc__
    assert "(height, width, 3)" in skydome.Dome.radiance.__doc__


def test_type_stubs_ship_with_the_package():
    pkg = Path(skydome.__file__).parent
    stub = (pkg / "__init__.pyi").read_text()
    assert (pkg / "py.typed").exists()
    for name in ("def run(", "def calibrate(", "def read_hdr(", "def write_hdr(", "def tonemap(",
                 "class Dome", "class CameraProfile", "class Error(ValueError)"):
        assert name in stub, name
