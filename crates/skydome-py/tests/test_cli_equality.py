"""The Python shell adds nothing: the same frames and options give the command line's bytes."""

import json

import numpy as np
import skydome
from conftest import demo_frames, run_cli, shared_dir


def test_real_bracket_hdr_is_byte_identical_to_the_cli(cli, tmp_path):
    # frobisher_001: three real Canon JPEGs, exposure times only in EXIF.
    frames = sorted(shared_dir("frobisher_001").glob("IMG_260*.jpg"))
    assert len(frames) == 3
    cli_hdr = tmp_path / "cli.hdr"
    p = run_cli(cli, "merge", *frames, "-o", cli_hdr, "--json")
    cli_report = json.loads(p.stdout)

    dome = skydome.run([str(f) for f in frames])
    py_hdr = tmp_path / "py.hdr"
    dome.save(py_hdr)

    assert py_hdr.read_bytes() == cli_hdr.read_bytes()
    cli_report.pop("written")
    assert dome.report == cli_report
    # The default calibration resolved for three frames, named as --method names it.
    assert dome.report["calibration"] == "joined"
    assert dome.radiance.shape == (cli_report["height"], cli_report["width"], 3)
    assert dome.radiance.dtype == np.float32


def test_fisheye_dome_with_every_product_matches_the_cli(cli, tmp_path):
    frames, times = demo_frames()
    t = ",".join(str(x) for x in times)
    out = {k: tmp_path / f"cli.{k}" for k in ("hdr", "exr")}
    eq = tmp_path / "cli_eq.hdr"
    prev = tmp_path / "cli_preview.png"
    p = run_cli(
        cli, "merge", *frames, "--times", t, "--fisheye", "--crop", "--north", 37,
        "--weighting", "noise", "-o", out["hdr"], "--exr", out["exr"], "--equirect", eq,
        "--equirect-width", 256, "--preview", prev, "--json",
    )
    cli_report = json.loads(p.stdout)

    dome = skydome.run(
        frames, times, fisheye=True, crop=True, north=37, weighting="noise",
        equirect=256, preview=True,
    )
    dome.save(tmp_path / "py.hdr")
    dome.save(tmp_path / "py.exr")
    dome.save_equirect(tmp_path / "py_eq.hdr")

    assert (tmp_path / "py.hdr").read_bytes() == out["hdr"].read_bytes()
    assert (tmp_path / "py.exr").read_bytes() == out["exr"].read_bytes()
    assert (tmp_path / "py_eq.hdr").read_bytes() == eq.read_bytes()
    cli_report.pop("written")
    assert dome.report == cli_report
    # The sun and north the header carries are the report's.
    assert dome.header["sun"] == cli_report["meta"]["sun"]
    assert dome.header["north"] is not None
    # The preview is the CLI's preview picture's pixels (PNG is lossless).
    assert dome.preview.shape == (dome.height, dome.width, 3)
    assert dome.preview.dtype == np.uint8


def test_profile_from_calibrate_matches_the_cli_camera_json(cli, tmp_path):
    frames, times = demo_frames()
    cam = tmp_path / "cam.json"
    run_cli(cli, "calibrate", *frames, "--times", ",".join(map(str, times)), "-o", cam)
    profile = skydome.calibrate(frames, times)
    assert profile.to_json() == cam.read_text()
    profile.save(tmp_path / "py.json")
    assert (tmp_path / "py.json").read_bytes() == cam.read_bytes()

    # And a merge with that profile, from a path and from the object, is the CLI's.
    cli_hdr = tmp_path / "cli.hdr"
    p = run_cli(
        cli, "merge", *frames, "--times", ",".join(map(str, times)), "--profile", cam,
        "-o", cli_hdr, "--json",
    )
    for given in (str(cam), skydome.CameraProfile.load(cam)):
        dome = skydome.run(frames, times, profile=given)
        dome.save(tmp_path / "py.hdr")
        assert (tmp_path / "py.hdr").read_bytes() == cli_hdr.read_bytes()
    # The report names the profile file as the CLI does.
    assert skydome.run(frames, times, profile=cam).report["response"] == json.loads(p.stdout)[
        "response"
    ]


def test_calibrate_methods_match_the_cli_on_a_five_frame_bracket(cli, tmp_path):
    # From five frames the default ("auto") is the covering calibration (2000 samples), as the
    # command line's; "robust" is the grid calibration at every count (about 100).
    run_cli(cli, "synth", "--size", 256, "--evs=-2,-1,0,1,2", "-o", tmp_path)
    frames = [str(tmp_path / f"frame_{k}.jpg") for k in range(5)]
    listed = dict(
        line.split()[:2]
        for line in (tmp_path / "times.txt").read_text().splitlines()
        if line and not line.startswith("#")
    )
    times = [float(listed[f"frame_{k}.jpg"]) for k in range(5)]
    t = ",".join(map(str, times))
    samples = {}
    for method in ("auto", "robust", "covering"):
        cam = tmp_path / f"cam_{method}.json"
        run_cli(cli, "calibrate", *frames, "--times", t, "--method", method, "-o", cam)
        profile = skydome.calibrate(frames, times, method=method)
        assert profile.to_json() == cam.read_text(), method
        samples[method] = json.loads(cam.read_text())["samples"]
    assert skydome.calibrate(frames, times).to_json() == (tmp_path / "cam_auto.json").read_text()
    assert samples["auto"] == samples["covering"] >= 2000 > 4 * samples["robust"]


def test_measured_exposures_match_the_cli(cli, tmp_path):
    # The demo bracket with its first frame's time listed a stop long, on the camera profile
    # made from the right times: the check names the frame, and exposures="measured" merges
    # on what the photos say, as `--exposures measured` does. (Self-calibrating, three frames
    # with one wrong time are ambiguous: docs/accuracy.md.)
    frames, times = demo_frames()
    profile = tmp_path / "camera.json"
    run_cli(cli, "calibrate", *frames, "--times", ",".join(str(x) for x in times), "-o", profile)
    wrong = [2 * times[0]] + times[1:]
    t = ",".join(str(x) for x in wrong)
    cli_hdr = tmp_path / "cli.hdr"
    p = run_cli(cli, "merge", *frames, "--times", t, "--profile", profile, "--exposures",
                "measured", "-o", cli_hdr, "--json")
    cli_report = json.loads(p.stdout)

    dome = skydome.run(frames, wrong, profile=profile, exposures="measured")
    dome.save(tmp_path / "py.hdr")
    assert (tmp_path / "py.hdr").read_bytes() == cli_hdr.read_bytes()
    cli_report.pop("written")
    assert dome.report == cli_report
    ex = dome.report["exposures"]
    assert ex["source"] == "measured"
    assert [f["off"] for f in ex["frames"]] == [True] + [False] * (len(frames) - 1)
    # A stop from the listed time, within 0.1 stops of the true one (measured 0.04).
    assert ex["frames"][0]["off_stops"] < -0.9
    assert abs(np.log2(ex["frames"][0]["measured_s"] / times[0])) < 0.1

    # The listed times are taken as they are (no measurement in the report).
    listed = skydome.run(frames, wrong, profile=profile)
    assert "exposures" not in listed.report
    assert listed.radiance.tobytes() != dome.radiance.tobytes()
