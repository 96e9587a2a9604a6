"""skydome.run mapped over several captures on a Dask cluster of worker processes gives what a
plain loop gives: the Dome pickles across processes and the core is deterministic."""

import numpy as np
import pytest
import skydome
from conftest import demo_frames

distributed = pytest.importorskip(
    "distributed", reason="dask[distributed] is not installed (pip install 'dask[distributed]')"
)


def test_dask_local_cluster_of_processes_matches_a_plain_loop(synth_brackets):
    captures = [demo_frames()] + list(synth_brackets)
    frames = [[str(p) for p in f] for f, _ in captures]
    times = [t for _, t in captures]
    options = dict(fisheye=True, crop=True, preview=True)

    expected = [skydome.run(f, t, **options) for f, t in zip(frames, times)]

    with distributed.LocalCluster(
        processes=True, n_workers=2, threads_per_worker=1, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as client:
        futures = client.map(skydome.run, frames, times, pure=False, **options)
        got = client.gather(futures)
        # The work really ran in the worker processes, not in this one.
        pids = set(client.run(lambda: __import__("os").getpid()).values())
        assert len(pids) == 2 and __import__("os").getpid() not in pids

    assert len(got) == len(expected) == 4
    for g, e in zip(got, expected):
        assert isinstance(g, skydome.Dome)
        assert np.array_equal(g.radiance, e.radiance)
        assert np.array_equal(g.preview, e.preview)
        assert g.header == e.header
        assert g.report == e.report
