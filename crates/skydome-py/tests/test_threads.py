"""The GIL is released while the core computes; progress, cancellation and Ctrl-C."""

import _thread
import signal
import sys
import threading

import numpy as np
import pytest
import skydome
from conftest import demo_frames, run_cli


@pytest.fixture(scope="module")
def long_bracket(cli, tmp_path_factory):
    """A 768 px synthetic bracket: a run long enough (a few hundred ms with the noise weighting)
    for another thread to be scheduled inside it."""
    d = tmp_path_factory.mktemp("long")
    run_cli(cli, "synth", "-o", d, "--size", 768, "--seed", 5)
    lines = [ln.split() for ln in (d / "times.txt").read_text().splitlines()
             if ln.strip() and not ln.startswith("#")]
    return [d / n for n, _ in lines], [float(t) for _, t in lines]


def test_two_threads_merge_two_brackets_at_once(long_bracket, synth_brackets):
    """With time-based GIL switching switched off (a switch interval of 1000 s), a thread that
    holds the GIL keeps it until it blocks or releases it. Thread B waits until thread A's run
    has started (A's first progress event), then runs its own job. Had A's core kept the GIL, B
    could not wake before A's run ended, and all of B's progress events would come after all of
    A's; they interleave only because the core runs without the GIL. (The one way this test can
    fail with the GIL released: B not scheduled at all during A's whole run.)"""
    (fa, ta), (fb, tb) = long_bracket, synth_brackets[1]
    a_started = threading.Event()
    events = []
    results = {}

    def progress_a(stage, fraction):
        events.append(("a", stage, fraction))
        a_started.set()

    def job_a():
        results["a"] = skydome.run(fa, ta, weighting="noise", progress=progress_a)

    def job_b():
        assert a_started.wait(120), "thread A never started"
        results["b"] = skydome.run(
            fb, tb, progress=lambda s, f: events.append(("b", s, f))
        )

    old = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)
    try:
        threads = [threading.Thread(target=job_b), threading.Thread(target=job_a)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(300)
    finally:
        sys.setswitchinterval(old)
    assert set(results) == {"a", "b"}, "a thread failed"
    who = [e[0] for e in events]
    first_b = who.index("b")
    last_a = len(who) - 1 - who[::-1].index("a")
    assert first_b < last_a, (
        "thread B ran only after thread A's run had ended: the GIL was not released "
        f"(events: {events})"
    )
    # Both results are what a lone run gives.
    assert np.array_equal(results["a"].radiance, skydome.run(fa, ta, weighting="noise").radiance)
    assert np.array_equal(results["b"].radiance, skydome.run(fb, tb).radiance)


def test_progress_reports_every_stage_in_order():
    frames, times = demo_frames()
    events = []
    skydome.run(frames, times, fisheye=True, crop=True, preview=True,
                progress=lambda s, f: events.append((s, f)))
    stages = []
    for s, f in events:
        assert 0.0 <= f <= 1.0
        if not stages or stages[-1] != s:
            stages.append(s)
    assert stages == ["decoding", "lens", "calibrating", "merging", "sky", "pictures"]
    assert events[0] == ("decoding", 0.0) and events[-1] == ("pictures", 1.0)


def test_an_exception_in_progress_cancels_and_propagates():
    frames, times = demo_frames()
    seen = []

    def progress(stage, fraction):
        seen.append(stage)
        if stage == "merging":
            raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        skydome.run(frames, times, progress=progress)
    assert seen[-1] == "merging" and "sky" not in seen


@pytest.fixture
def python_handles_ctrl_c():
    """Python's own SIGINT handler, as in an interactive session. A process started in the
    background by a non-interactive shell (as CI runs) inherits SIGINT ignored; Python then
    installs no handler and `_thread.interrupt_main()` does nothing."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def test_ctrl_c_cancels_a_run(python_handles_ctrl_c):
    """Ctrl-C (here: SIGINT simulated from inside a progress event, as Ctrl-C would arrive
    while the core runs) ends the run with KeyboardInterrupt before the next stage."""
    frames, times = demo_frames()
    seen = []

    def progress(stage, fraction):
        seen.append(stage)
        if stage == "calibrating" and fraction == 0.0:
            _thread.interrupt_main()

    with pytest.raises(KeyboardInterrupt):
        skydome.run(frames, times, progress=progress)
    assert "merging" not in seen
    # calibrate() too.
    with pytest.raises(KeyboardInterrupt):
        skydome.calibrate(frames, times, progress=progress)
