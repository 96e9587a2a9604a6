"""Frames as paths, bytes and numpy arrays; bad input raises the right exception and message."""

import os
from pathlib import Path

import numpy as np
import pytest
import skydome
from conftest import demo_frames, photograph, run_cli, write_png


@pytest.fixture(scope="module")
def scene():
    """A real sky's radiance (the bundled demo's truth.hdr) photographed at 1/400, 1/100, 1/25 s
    through a gamma response, as uint8 arrays, and the same frames as lossless PNG files."""
    radiance, _ = skydome.read_hdr(Path(__file__).resolve().parents[3] / "demo" / "truth.hdr")
    times = [1 / 400, 1 / 100, 1 / 25]
    return radiance, times


def test_arrays_paths_and_bytes_give_the_same_dome(scene, tmp_path):
    radiance, times = scene
    frames = photograph(radiance, times)
    paths = []
    for i, f in enumerate(frames):
        paths.append(tmp_path / f"f{i}.png")
        write_png(paths[-1], f)
    from_arrays = skydome.run(frames, times, fisheye=True, crop=True)
    from_paths = skydome.run(paths, times, fisheye=True, crop=True)
    from_bytes = skydome.run([p.read_bytes() for p in paths], times, fisheye=True, crop=True)
    from_stack = skydome.run(np.stack(frames), times, fisheye=True, crop=True)
    from_views = skydome.run([np.asfortranarray(f) for f in frames], times, fisheye=True, crop=True)
    for other in (from_paths, from_bytes, from_stack, from_views):
        assert np.array_equal(other.radiance, from_arrays.radiance)
        assert other.header == from_arrays.header
    # The reports differ only in the frames' names.
    a, p = from_arrays.report, from_paths.report
    assert [f["file"] for f in a["frames"]] == ["frames[0]", "frames[1]", "frames[2]"]
    assert [f["file"] for f in p["frames"]] == [str(x) for x in paths]
    for r in (a, p):
        for f in r["frames"]:
            f.pop("file")
    assert a == p
    # The input arrays are untouched (copied, never changed in place).
    assert np.array_equal(frames[1], photograph(radiance, times)[1])


def test_sixteen_bit_arrays_and_pngs_agree(scene, tmp_path):
    radiance, times = scene
    frames = photograph(radiance[::2, ::2].copy(), times, bits=16)
    for i, f in enumerate(frames):
        write_png(tmp_path / f"f{i}.png", f)
    a = skydome.run(frames, times)
    p = skydome.run([tmp_path / f"f{i}.png" for i in range(3)], times)
    assert np.array_equal(a.radiance, p.radiance)


def test_mismatched_sizes(scene):
    radiance, times = scene
    frames = photograph(radiance, times)
    frames[1] = frames[1][:-8]
    h, w = frames[0].shape[:2]
    with pytest.raises(skydome.Error) as e:
        skydome.run(frames, times)
    assert str(e.value) == (
        f"frames[1] ({w}x{h - 8}): size differs from frames[0] ({w}x{h}); "
        "all frames must have the same size"
    )


def test_corrupt_bytes_and_files_name_the_frame(cli, tmp_path):
    frames, times = demo_frames()
    good = [f.read_bytes() for f in frames]
    with pytest.raises(skydome.Error, match=r"^frames\[1\]: unsupported or unrecognised image format"):
        skydome.run([good[0], b"not an image at all", good[2]], times)
    truncated = good[1][: len(good[1]) // 2]
    with pytest.raises(skydome.Error, match=r"^frames\[1\]: "):
        skydome.run([good[0], truncated, good[2]], times)
    # A corrupt file: the message is the CLI's, naming the path.
    bad = tmp_path / "bad.jpg"
    bad.write_bytes(truncated)
    paths = [frames[0], bad, frames[2]]
    with pytest.raises(skydome.Error) as e:
        skydome.run(paths, times)
    p = run_cli(cli, "merge", *paths, "--times", ",".join(map(str, times)),
                "-o", tmp_path / "x.hdr", check=False)
    assert p.returncode == 1
    assert p.stderr.strip() == f"error: {e.value}"
    assert str(e.value).startswith(f"{bad}: ")
    assert not (tmp_path / "x.hdr").exists()


def test_missing_file():
    with pytest.raises(skydome.Error, match=r"^/no/such/frame\.jpg: cannot read"):
        skydome.run(["/no/such/frame.jpg", "/no/such/other.jpg"], [1.0, 4.0])


def test_wrong_dtype_and_shape(scene):
    radiance, times = scene
    frames = photograph(radiance, times)
    with pytest.raises(TypeError, match=r"^frames\[2\]: expected a uint8 or uint16 array .*got dtype float32; convert with"):
        skydome.run(frames[:2] + [frames[2].astype(np.float32)], times)
    with pytest.raises(ValueError, match=r"^frames\[0\]: expected an array of shape \(height, width, 3\).*got shape \(\d+, \d+\)$"):
        skydome.run([frames[0][..., 0]] + frames[1:], times)
    with pytest.raises(ValueError, match=r"shape \(\d+, \d+, 4\)"):
        skydome.run([np.dstack([f, f[..., :1]]) for f in frames], times)
    with pytest.raises(TypeError, match=r"^frames\[1\]: expected a path .* got int"):
        skydome.run([frames[0], 7], times)
    with pytest.raises(TypeError, match="^frames: expected a list of frames"):
        skydome.run("sky.jpg")


def test_missing_times(scene, cli, tmp_path):
    radiance, times = scene
    frames = photograph(radiance, times)
    with pytest.raises(ValueError, match=r"^times: frames\[0\] is a numpy array, which carries no exposure time"):
        skydome.run(frames)
    # Files without EXIF: the CLI's message, with the keyword instead of the flag.
    paths, _ = demo_frames()
    with pytest.raises(skydome.Error) as e:
        skydome.run(paths)
    p = run_cli(cli, "merge", *paths, "-o", tmp_path / "x.hdr", check=False)
    cli_msg = p.stderr.strip().removeprefix("error: ")
    # Every file without a time is named (issue 28), the first ones comma-separated.
    named = ", ".join(str(q) for q in paths[:-1]) + f" and {paths[-1]}"
    assert cli_msg.startswith(f"{named}: no exposure time in EXIF; supply the exposure times with --times")
    assert str(e.value) == cli_msg.split(" with --times")[0] + (
        " with times=[1/400, 1/100, ...] (seconds, one per frame, in the order given)"
    )
    with pytest.raises(skydome.Error, match="--times has|exposure times"):
        skydome.run(paths, [0.01, 0.02])
    with pytest.raises(TypeError, match=r"^times\[1\]: expected a number of seconds, got str"):
        skydome.run(paths, [0.001, "1/250", 0.016])


def test_bad_arguments_name_the_argument():
    frames, times = demo_frames()
    cases = [
        (dict(weighting="bogus"), ValueError, "^weighting: 'bogus' is not a weighting; expected one of: none, hat, noise"),
        (dict(exposures="guessed"), ValueError, "^exposures: 'guessed' is not a"),
        (dict(sun=5), TypeError, "^sun: expected 'auto', 'none', 'ephemeris' or \\(x, y\\)"),
        (dict(sun="moon"), ValueError, "^sun: 'moon'"),
        (dict(north="south"), ValueError, "^north: 'south'"),
        (dict(progress=3), TypeError, "^progress: expected a callable"),
        (dict(fov=180.0), ValueError, "^fov: describes the nominal lens of fisheye=True"),
        (dict(fisheye=True, lens_model="fancy"), ValueError, "^lens_model: "),
        (dict(luminance=(1.0, 2.0)), ValueError, "^luminance: expected \\(x, y, cd_per_m2\\)"),
        (dict(profile=42), TypeError, "^profile: expected a skydome.CameraProfile or the path"),
        (dict(equirect="yes"), ValueError, "^equirect: "),
        (dict(fisheye=True, time=12), TypeError, "^time: expected ISO 8601"),
    ]
    for kwargs, exc, pattern in cases:
        with pytest.raises(exc, match=pattern):
            skydome.run(frames, times, **kwargs)
    # Options that need a lens: the library's message with the keyword that fixes it.
    with pytest.raises(skydome.Error, match=r"^cropping to the dome needs a fish-eye lens .*\(lens='lens.json' or fisheye=True\)$"):
        skydome.run(frames, times, crop=True)
    assert issubclass(skydome.Error, ValueError)


def test_pathlike_frames_are_accepted():
    frames, times = demo_frames()
    a = skydome.run([os.fspath(f) for f in frames], times)
    b = skydome.run(frames, times)
    assert np.array_equal(a.radiance, b.radiance)
