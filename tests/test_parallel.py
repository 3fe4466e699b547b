"""The chunk loop on workers: same outputs for 1 and 2 processes, any chunk size, and Dask."""

from __future__ import annotations

import json
import operator
import threading
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from pipeline.parallel import Executor, _ordered
from pipeline.run import run_scene
from pipeline.scene import parse_scene
from tests.conftest import ROOT

#: evaluation.json entries that are clock readings, not results
_TIMINGS = ("stages", "seconds_per_pulse", "timings_s")


def test_results_come_in_task_order_with_at_most_ahead_pending():
    """Tasks finishing in reverse order still come out 0, 1, 2, ...; never > ahead in flight."""
    lock, state = threading.Lock(), {"pending": 0, "most": 0}

    def task(i):
        time.sleep(0.02 * (5 - i % 5))  # later tasks of a window finish first
        return i * i

    with ThreadPoolExecutor(4) as pool:

        def submit(i):
            with lock:
                state["pending"] += 1
                state["most"] = max(state["most"], state["pending"])
            return pool.submit(task, i)

        out = []
        for r in _ordered(submit, 12, ahead=3):
            with lock:
                state["pending"] -= 1
            out.append(r)
    assert out == [i * i for i in range(12)]
    assert state["most"] == 3


def test_serial_executor_maps_in_order():
    with Executor(workers=1) as ex:
        assert list(ex.map(operator.getitem, [5, 6, 7], 3)) == [5, 6, 7]
        assert ex.describe()["engine"] == "serial"
    with pytest.raises(ValueError):
        Executor(workers=0)


def _worker_of(shared, i, data):
    from distributed import get_worker

    return get_worker().address, data["k"]


def _task_with_data(shared, i, data):
    return shared[i] * 10 + data["k"], data["block"].sum()


@pytest.mark.parametrize("engine", ["serial", "pool", "dask"])
def test_a_task_is_sent_its_own_data_made_here_as_it_is_submitted(engine):
    """``payload(i)`` reaches task ``i`` alone, whole, and never more than ``ahead`` are made
    before their results are taken (brute force: what each task must return)."""
    made = []

    def payload(i):
        made.append(i)
        # a dict (Dask would scatter its items one by one if given it bare) with an array
        return {"k": i, "block": np.full(50_000, float(i))}

    shared, n, ahead = [3, 1, 4, 1, 5, 9, 2], 7, 2
    want = [(shared[i] * 10 + i, 50_000.0 * i) for i in range(n)]

    def check(ex):
        got = []
        for i, r in enumerate(ex.map(_task_with_data, shared, n, ahead=ahead, payload=payload)):
            assert max(made) <= i + ahead - 1  # made only as a task is submitted
            got.append(r)
        assert got == want and made == list(range(n))

    if engine == "dask":
        from distributed import LocalCluster

        with LocalCluster(n_workers=2, threads_per_worker=1, processes=False) as cluster:
            with Executor(scheduler=cluster.scheduler_address) as ex:
                check(ex)
                memory = ex.cluster_memory()
                assert [t for _, t, _ in memory] == [1, 1]
                assert all(0.0 <= free < float("inf") for _, _, free in memory)
                # tasks and their data given slots: all on the one worker listed (twice)
                first = memory[0][0]
                got = list(ex.map(_worker_of, None, 5, payload=payload, slots=[first, first]))
                assert got == [(first, i) for i in range(5)]
    else:
        check(Executor(workers=1 if engine == "serial" else 2))


def test_pool_workers_read_shared_once_from_an_unnamed_file():
    """The workers read ``shared`` from a file that has no name and is gone after the pool."""
    import os

    from pipeline import parallel
    from pipeline.parallel import _install_from, _shared_handoff

    big = np.arange(300_000, dtype=np.float64)  # 2.4 MB: far more than a pipe holds
    with _shared_handoff(big) as (init, args):
        assert init is _install_from
        (path,) = args
        assert path.startswith(f"/proc/{os.getpid()}/fd/")
        # unnamed: the link names no file in any folder
        assert "(deleted)" in os.readlink(path) or os.readlink(path).startswith("/memfd")
        init(path)  # what each worker runs: the object, whole
        assert np.array_equal(parallel._SHARED, big)
        parallel._SHARED = None
    assert not os.path.exists(path)
    # (a pool reading it: test_outputs_identical_for_workers_chunk_sizes_and_dask)


def _scene(chunk_pulses: int):
    data = tomllib.loads((ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text())
    data["flight"]["area_m"] = [0.0, 60.0, 0.0, 60.0]
    data["flight"]["run_in_m"] = 60.0
    data["scanner"]["prf_hz"] = 3000.0
    data["process"]["posterior_pulses_per_km2"] = 0.0
    data["process"]["posterior_min_pulses"] = 0
    data["run"] = {"chunk_pulses": chunk_pulses}
    return parse_scene(data)


def _outputs(out):
    """Every LAS dimension, every grid band and the evaluation's figures (clock readings out)."""
    import laspy
    import rasterio

    las = laspy.read(out / "points.laz")
    points = {d: np.asarray(las[d]) for d in las.point_format.dimension_names}
    with rasterio.open(out / "grid.tif") as r:
        bands = r.read()

    def drop(x):
        if isinstance(x, dict):
            return {k: drop(v) for k, v in x.items() if k not in _TIMINGS}
        return [drop(v) for v in x] if isinstance(x, list) else x

    ev = drop(json.loads((out / "evaluation.json").read_text()))
    return points, bands, ev


def _assert_same(a, b):
    pa, ga, ea = a
    pb, gb, eb = b
    assert pa.keys() == pb.keys()
    for d in pa:
        np.testing.assert_array_equal(pa[d], pb[d], err_msg=d)
    np.testing.assert_array_equal(ga, gb)  # NaN (empty cells) compare equal here
    assert json.dumps(ea, sort_keys=True) == json.dumps(eb, sort_keys=True)


@pytest.mark.slow
def test_outputs_identical_for_workers_chunk_sizes_and_dask(tmp_path):
    log = lambda _: None  # noqa: E731
    runs = {}
    for name, chunk, workers in (("w1_big", 4000, 1), ("w2_big", 4000, 2), ("w2_small", 900, 2)):
        out = tmp_path / name
        man = run_scene(_scene(chunk), out, log=log, workers=workers)
        assert man["execution"]["workers"] == workers
        runs[name] = _outputs(out)
    from distributed import LocalCluster

    # threads, not processes: a process cluster would start 2 more interpreters on 2 cores
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False) as cluster:
        out = tmp_path / "dask"
        address = cluster.scheduler_address
        man = run_scene(_scene(900), out, log=log, workers=None, scheduler=address)
        ex = man["execution"]
        assert (ex["workers"], ex["scheduler"], ex["engine"]) == (2, address, "dask")
        runs["dask"] = _outputs(out)
    ref = runs.pop("w1_big")
    assert len(ref[0]["X"]) > 1000  # a survey's worth of points, not an empty comparison
    assert ref[2]["pulses"] > 5000  # 3 chunks of 4000, 11 of 900
    for got in runs.values():
        _assert_same(ref, got)
