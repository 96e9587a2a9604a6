#!/usr/bin/env python3
"""skydome from Python against the command line on a 6 MP bracket.

    cargo build --release -p skydome-cli
    pip install ./crates/skydome-py          # into the Python that runs this
    python scripts/bench_python.py [--size 2448] [--runs 5]

Makes a synthetic fish-eye bracket (`skydome synth --size 2448`: 3 JPEGs of 6 MP), then times,
alternately, RUNS times each:
  cli     `skydome merge FRAMES --times T --fisheye --crop -o cli.hdr --force --quiet`
          (a whole process: start, read, decode, merge, encode, write);
  python  `skydome.run(FRAMES, T, fisheye=True, crop=True).save("py.hdr")` in this process
          (the same work; the module is imported once, before timing);
and prints the median and minimum wall time and the median CPU time (user + system, every
thread; the CLI's as its child's rusage) of each, and python / cli (target <= 1.05). CPU time
is the steadier figure on a shared machine. Both outputs are checked byte for byte.

Run it on a quiet machine; it is a benchmark, not a test.
"""

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=2448, help="image side in pixels (2448: 6 MP)")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--cli", default=str(REPO / "target" / "release" / "skydome"))
    a = ap.parse_args()

    import skydome

    cli = a.cli
    if not Path(cli).exists():
        sys.exit(f"{cli}: not found; run `cargo build --release -p skydome-cli` first")
    with tempfile.TemporaryDirectory(prefix="skydome-bench-") as tmp:
        tmp = Path(tmp)
        subprocess.run([cli, "--quiet", "synth", "-o", tmp, "--size", str(a.size)], check=True)
        lines = [
            ln.split()
            for ln in (tmp / "times.txt").read_text().splitlines()
            if ln.strip() and not ln.startswith("#")
        ]
        frames = [str(tmp / n) for n, _ in lines]
        times = [float(t) for _, t in lines]
        tlist = ",".join(t for _, t in lines)
        cmd = [cli, "--quiet", "merge", *frames, "--times", tlist, "--fisheye", "--crop",
               "-o", str(tmp / "cli.hdr"), "--force"]

        def run_cli():
            subprocess.run(cmd, check=True)

        def run_py():
            skydome.run(frames, times, fisheye=True, crop=True).save(tmp / "py.hdr")

        # One untimed run of each (page cache, lazy initialisation).
        run_cli()
        run_py()
        assert (tmp / "cli.hdr").read_bytes() == (tmp / "py.hdr").read_bytes(), "outputs differ"

        def cpu_cli():
            r = resource.getrusage(resource.RUSAGE_CHILDREN)
            return r.ru_utime + r.ru_stime

        t_cli, t_py, c_cli, c_py = [], [], [], []
        for _ in range(a.runs):
            for f, acc, cacc, cpu in ((run_cli, t_cli, c_cli, cpu_cli),
                                      (run_py, t_py, c_py, time.process_time)):
                c0 = cpu()
                t0 = time.perf_counter()
                f()
                acc.append(time.perf_counter() - t0)
                cacc.append(cpu() - c0)

        mp = a.size * a.size / 1e6
        print(f"bracket: 3 x {a.size}x{a.size} ({mp:.1f} MP) JPEG, fisheye + crop, {a.runs} runs each, "
              f"{os.cpu_count()} CPUs")
        for name, t, c in (("cli", t_cli, c_cli), ("python", t_py, c_py)):
            print(f"{name:>7}: wall median {statistics.median(t):.3f} s, min {min(t):.3f} s; "
                  f"CPU median {statistics.median(c):.3f} s")
        print(f"python / cli: wall median {statistics.median(t_py) / statistics.median(t_cli):.3f}, "
              f"min {min(t_py) / min(t_cli):.3f}; CPU median "
              f"{statistics.median(c_py) / statistics.median(c_cli):.3f}  (target <= 1.05)")


if __name__ == "__main__":
    main()
