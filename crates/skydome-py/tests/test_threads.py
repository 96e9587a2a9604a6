"""The GIL is released while the core computes; progress, cancellation and Ctrl-C."""

import _thread
import threading

import numpy as np
import pytest
import skydome
from conftest import demo_frames


def test_two_threads_merge_two_brackets_at_once(synth_brackets):
    """Thread A marks when it enters the merge (a progress event) and when it leaves it; thread
    B, started once A is inside, records what it sees from its own progress callback. B's Python
    code can run while A is between those two events only if A's core released the GIL: with
    the GIL held through the core, B would see A 'in the merge' never (A's events would all come
    before any of B's). The noise weighting makes A's merge the longest stage (about 0.1-0.3 s on
    this bracket), so B is scheduled inside it with a wide margin."""
    (fa, ta), (fb, tb) = synth_brackets[0], synth_brackets[1]
    a_in_core = threading.Event()
    a_left = threading.Event()
    seen_by_b = []
    events = []

    def progress_a(stage, fraction):
        events.append(("a", stage, fraction))
        if stage == "merging" and fraction == 0.0:
            a_in_core.set()
        if stage == "merging" and fraction == 1.0:
            a_left.set()

    def progress_b(stage, fraction):
        events.append(("b", stage, fraction))
        seen_by_b.append(a_in_core.is_set() and not a_left.is_set())

    results = {}

    def job_a():
        results["a"] = skydome.run(fa, ta, weighting="noise", progress=progress_a)

    def job_b():
        assert a_in_core.wait(120), "thread A never reached its merge"
        results["b"] = skydome.run(fb, tb, progress=progress_b)

    threads = [threading.Thread(target=job_a), threading.Thread(target=job_b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300)
    assert set(results) == {"a", "b"}, "a thread failed"
    assert any(seen_by_b), (
        "thread B never ran Python while thread A was inside its merge: the GIL was not "
        f"released (events: {events})"
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


def test_ctrl_c_cancels_a_run():
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
