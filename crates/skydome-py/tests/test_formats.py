"""read_hdr, write_hdr, tonemap, CameraProfile and pickling."""

import pickle

import numpy as np
import pytest
import skydome
from conftest import demo_frames


@pytest.fixture(scope="module")
def dome():
    frames, times = demo_frames()
    return skydome.run(frames, times, fisheye=True, crop=True, north=37, preview=True)


def test_write_hdr_of_a_dome_is_the_dome_s_file(dome, tmp_path):
    dome.save(tmp_path / "a.hdr")
    skydome.write_hdr(tmp_path / "b.hdr", dome.radiance, dome.header)
    assert (tmp_path / "a.hdr").read_bytes() == (tmp_path / "b.hdr").read_bytes()


def test_read_hdr_gives_the_radiance_within_rgbe_precision(dome, tmp_path):
    dome.save(tmp_path / "a.hdr")
    arr, header = skydome.read_hdr(tmp_path / "a.hdr")
    assert arr.dtype == np.float32 and arr.shape == dome.radiance.shape
    # The header lines carry what the dome's header says (angles printed to 1e-6 degrees).
    want = dome.header
    assert header["view"] == want["view"] and header["north"] == want["north"]
    assert header["capdate"] == want["capdate"] and header["other"] == want["other"]
    assert header["sun"]["pixel"] == want["sun"]["pixel"]
    assert abs(header["sun"]["azimuth_deg"] - want["sun"]["azimuth_deg"]) < 1e-6
    assert header["software"] == f"skydome {skydome.__version__}"
    # RGBE keeps 8 bits of mantissa per channel against the pixel's largest: the largest
    # channel of each pixel is within 1/128 (relative).
    big = dome.radiance.max(axis=2)
    got = arr.max(axis=2)
    lit = big > 1e-30
    rel = np.abs(got[lit] - big[lit]) / big[lit]
    assert rel.max() <= 1 / 128
    # The array is the reader's own, writable buffer.
    arr[0, 0, 0] = 1.0


def test_write_hdr_applies_the_header_exposure(tmp_path):
    rng = np.random.default_rng(3)
    rad = rng.uniform(0.01, 100.0, size=(16, 24, 3)).astype(np.float32)
    skydome.write_hdr(tmp_path / "e.hdr", rad, {"exposure": 0.25})
    back, header = skydome.read_hdr(tmp_path / "e.hdr")
    assert header["exposure"] == 0.25
    # RGBE: each channel within 1/128 of the pixel's largest channel.
    assert np.all(np.abs(back - rad) <= rad.max(axis=2, keepdims=True) / 128)
    skydome.write_hdr(tmp_path / "e.exr", rad.astype(np.float64))
    back, _ = skydome.read_hdr(tmp_path / "e.exr")
    assert np.allclose(back, rad, rtol=1e-3)  # half float: 11 bits of mantissa


def test_write_hdr_refuses_bad_headers_and_extensions(tmp_path):
    rad = np.ones((4, 4, 3), np.float32)
    with pytest.raises(ValueError, match="header: unknown key 'exposur'"):
        skydome.write_hdr(tmp_path / "a.hdr", rad, {"exposur": 2.0})
    with pytest.raises(ValueError, match=r"cannot write '\.png' radiance files; use \.hdr or \.exr"):
        skydome.write_hdr(tmp_path / "a.png", rad)
    with pytest.raises(TypeError, match="array: expected radiance as float32 or float64, got dtype"):
        skydome.write_hdr(tmp_path / "a.hdr", rad.astype(np.uint8))
    assert not list(tmp_path.iterdir())


def test_read_hdr_names_the_file(tmp_path):
    bad = tmp_path / "bad.hdr"
    bad.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +X 4\n\x02")
    with pytest.raises(skydome.Error, match=f"^{bad}: "):
        skydome.read_hdr(bad)
    with pytest.raises(skydome.Error, match="cannot read"):
        skydome.read_hdr(tmp_path / "missing.hdr")


def test_tonemap_is_the_preview_and_takes_the_cli_options(dome):
    assert np.array_equal(skydome.tonemap(dome.radiance), dome.preview)
    sixteen = skydome.tonemap(dome.radiance, "reinhard", bits=16)
    assert sixteen.dtype == np.uint16 and sixteen.shape == dome.radiance.shape
    dark = skydome.tonemap(dome.radiance, "linear", exposure=-20)
    bright = skydome.tonemap(dome.radiance, "linear", exposure=20)
    assert dark.mean() < bright.mean()
    with pytest.raises(ValueError, match="op: unknown tone-mapping operator 'filmicx'"):
        skydome.tonemap(dome.radiance, "filmicx")
    with pytest.raises(ValueError, match="key = 0 is out of range"):
        skydome.tonemap(dome.radiance, key=0.0)


def test_result_arrays_are_read_only_views(dome):
    r = dome.radiance
    assert not r.flags.writeable
    with pytest.raises(ValueError):
        r[0, 0, 0] = 1.0
    # A view of the dome's buffer, not a copy: two accesses share memory.
    assert np.shares_memory(dome.radiance, dome.radiance)
    assert np.array(r).flags.writeable


def test_dome_and_profile_pickle(dome, tmp_path):
    back = pickle.loads(pickle.dumps(dome))
    assert np.array_equal(back.radiance, dome.radiance)
    assert np.array_equal(back.preview, dome.preview)
    assert back.report == dome.report and back.header == dome.header
    dome.save(tmp_path / "a.hdr")
    back.save(tmp_path / "b.hdr")
    assert (tmp_path / "a.hdr").read_bytes() == (tmp_path / "b.hdr").read_bytes()
    prof = dome.camera_profile
    assert pickle.loads(pickle.dumps(prof)) == prof


def test_camera_profile_round_trip_and_errors(dome, tmp_path):
    prof = dome.camera_profile
    assert prof.g.shape == (3, 256)
    assert abs(prof.g[1, 128]) < 1e-9  # g(128) = 0
    assert np.all(np.diff(prof.g, axis=1) >= 0)  # non-decreasing
    prof.save(tmp_path / "cam.json")
    loaded = skydome.CameraProfile.load(tmp_path / "cam.json")
    assert (tmp_path / "cam.json").read_text() == prof.to_json()
    # JSON text round-trips to within the last bit of the library's JSON float parser.
    assert np.allclose(loaded.g, prof.g, rtol=1e-15, atol=1e-15)
    assert skydome.CameraProfile.from_json(prof.to_json()).to_dict().keys() == prof.to_dict().keys()
    assert prof.to_dict()["version"] == 1
    (tmp_path / "bad.json").write_text('{"version": 7}')
    with pytest.raises(skydome.Error, match=f"^{tmp_path / 'bad.json'}: "):
        skydome.CameraProfile.load(tmp_path / "bad.json")
    with pytest.raises(skydome.Error, match=f"^{tmp_path / 'bad.json'}: "):
        frames, times = demo_frames()
        skydome.run(frames, times, profile=tmp_path / "bad.json")


def test_save_never_overwrites_an_input(tmp_path):
    frames, times = demo_frames()
    copies = []
    for f in frames:
        # Named .hdr (the decoder goes by content), so that save() could be pointed at it.
        c = tmp_path / (f.stem + ".hdr")
        c.write_bytes(f.read_bytes())
        copies.append(c)
    dome = skydome.run(copies, times)
    before = copies[0].read_bytes()
    with pytest.raises(skydome.Error, match="refusing to overwrite an input file"):
        dome.save(copies[0])
    assert copies[0].read_bytes() == before
    with pytest.raises(skydome.Error, match="does not exist"):
        dome.save(tmp_path / "no" / "such" / "dir.hdr")
