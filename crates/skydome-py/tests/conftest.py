"""Shared fixtures: the repository, the release CLI to compare with, brackets to run on.

The CLI is built with `cargo build --release -p skydome-cli` (a no-op when it is up to date)
unless SKYDOME_CLI names a binary. Tests on ../shared/data skip with a message when it is
absent, and fail instead when SKYDOME_REQUIRE_SHARED_DATA=1 (as CI sets it).
"""

import os
import shutil
import struct
import subprocess
import zlib
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[3]
DEMO = REPO / "demo"
SHARED = REPO.parent / "shared" / "data"


def demo_frames():
    """The bundled fish-eye bracket (no EXIF) and its exposure times in seconds."""
    lines = [
        ln.split()
        for ln in (DEMO / "times.txt").read_text().splitlines()
        if ln.strip() and not ln.startswith("#")
    ]
    return [DEMO / name for name, _ in lines], [float(t) for _, t in lines]


def shared_dir(name):
    """A folder of ../shared/data, or a skip (a failure under SKYDOME_REQUIRE_SHARED_DATA=1)."""
    d = SHARED / name
    if d.is_dir():
        return d
    msg = f"{d} is absent (the shared photo sets sit beside the repository)"
    if os.environ.get("SKYDOME_REQUIRE_SHARED_DATA") == "1":
        pytest.fail(msg + "; SKYDOME_REQUIRE_SHARED_DATA=1 requires it")
    pytest.skip(msg)


@pytest.fixture(scope="session")
def cli():
    """The path of the release `skydome` binary, built if needed."""
    env = os.environ.get("SKYDOME_CLI")
    if env:
        return Path(env)
    cargo = shutil.which("cargo")
    if cargo is None:
        pytest.fail("cargo is not on PATH: set SKYDOME_CLI to a built `skydome` binary")
    subprocess.run(
        [cargo, "build", "--release", "--quiet", "-p", "skydome-cli"], cwd=REPO, check=True
    )
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    return target / "release" / "skydome"


def run_cli(cli, *args, check=True):
    """Runs the CLI quietly; returns the completed process (stdout, stderr as text)."""
    p = subprocess.run(
        [str(cli), "--quiet", *map(str, args)], capture_output=True, text=True
    )
    if check and p.returncode != 0:
        raise AssertionError(f"skydome {' '.join(map(str, args))} failed: {p.stderr}")
    return p


@pytest.fixture(scope="session")
def synth_brackets(cli, tmp_path_factory):
    """Three small synthetic fish-eye brackets (`skydome synth`, 192 px, seeds 1-3), as
    (frame paths, times) pairs."""
    out = []
    for seed in (1, 2, 3):
        d = tmp_path_factory.mktemp(f"synth{seed}")
        run_cli(cli, "synth", "-o", d, "--size", 192, "--seed", seed)
        lines = [
            ln.split()
            for ln in (d / "times.txt").read_text().splitlines()
            if ln.strip() and not ln.startswith("#")
        ]
        out.append(([d / n for n, _ in lines], [float(t) for _, t in lines]))
    return out


def photograph(radiance, times, bits=8, gamma=2.2):
    """Frames (H, W, 3) of a radiance map through a gamma response: codes =
    round(max * clip(radiance * t / scale) ** (1 / gamma)), with scale putting the median of the
    middle exposure at mid-grey."""
    top = 255 if bits == 8 else 65535
    mid = sorted(times)[len(times) // 2]
    scale = float(np.median(radiance[radiance > 0])) * mid / 0.2
    frames = []
    for t in times:
        v = np.clip(radiance * (t / scale), 0.0, 1.0) ** (1.0 / gamma)
        frames.append(np.round(v * top).astype(np.uint8 if bits == 8 else np.uint16))
    return frames


def write_png(path, frame):
    """A minimal PNG writer (RGB, 8 or 16 bits, no filter): lossless, so the core decodes the
    very codes of `frame`."""
    h, w, _ = frame.shape
    bits = 8 if frame.dtype == np.uint8 else 16
    raw = frame.astype(">u2").tobytes() if bits == 16 else frame.tobytes()
    row = w * 3 * bits // 8
    data = b"".join(b"\x00" + raw[y * row : (y + 1) * row] for y in range(h))

    def chunk(kind, body):
        c = struct.pack(">I", len(body)) + kind + body
        return c + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", w, h, bits, 2, 0, 0, 0)
    Path(path).write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(data, 6))
        + chunk(b"IEND", b"")
    )
