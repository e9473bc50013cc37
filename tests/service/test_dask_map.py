"""The service's Dask map (service.diagnosis.dask_map): results in order and streamed, so a
diagnosis' store keeps the finished parts of an interrupted batch; a cancel or a shutdown (the same
stop event) ends a batch while it waits, and the batch's unstarted parts never run."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from service.diagnosis import DiagnosisCancelled, dask_map


class _Marked:
    """Squares a part after ``delay`` seconds and leaves a file per finished part in ``folder``."""

    def __init__(self, folder: Path, delay: float):
        self.folder, self.delay = str(folder), delay

    def __call__(self, part):
        time.sleep(self.delay)
        (Path(self.folder) / f"{float(part.ravel()[0]):g}.done").touch()
        return np.square(part)


def _parts(n: int) -> list[np.ndarray]:
    return [np.full((2, 1), float(k)) for k in range(n)]


def test_results_come_in_order_and_equal_the_builtin_map(dask_client, tmp_path):
    parts = [np.random.default_rng(k).standard_normal((3, 2)) for k in range(7)]
    got = list(dask_map(dask_client)(np.square, parts))
    assert all(a.tobytes() == b.tobytes() for a, b in zip(got, map(np.square, parts))) and len(got) == 7
    assert dask_map(None) is map  # no cluster: the builtin map


def test_a_cancel_or_a_shutdown_ends_the_batch_while_it_waits(dask_client, tmp_path):
    stop = threading.Event()
    fn = _Marked(tmp_path, 1.0)
    timer = threading.Timer(0.4, stop.set)  # set while the first parts still run
    got = []
    timer.start()
    try:
        with pytest.raises(DiagnosisCancelled):
            for v in dask_map(dask_client, stop)(fn, _parts(10)):
                got.append(v)
    finally:
        timer.cancel()
    assert len(got) < 10
    time.sleep(2.5)  # long enough for several more parts, had they not been cancelled
    # 10 parts of 1 s on 2 workers: at most the parts already running when it was set (2), and
    # those a worker had taken before the cancel reached it, finish; never the whole batch
    assert len(list(tmp_path.glob("*.done"))) <= 4


def test_the_store_keeps_the_parts_finished_before_a_cancel(dask_client, tmp_path):
    from vfcore.inference.memo import CachedMap

    stop = threading.Event()
    (tmp_path / "marks").mkdir()
    fn = _Marked(tmp_path / "marks", 0.3)
    store = CachedMap(dask_map(dask_client, stop), tmp_path / "store")

    def cancel_once_a_part_is_stored():  # not a fixed delay: a loaded machine starts workers slowly
        t0 = time.monotonic()
        while not any(store.root.rglob("*.pkl")) and time.monotonic() - t0 < 60:
            time.sleep(0.02)
        stop.set()

    watcher = threading.Thread(target=cancel_once_a_part_is_stored, daemon=True)
    watcher.start()
    with pytest.raises(DiagnosisCancelled):
        store(fn, _parts(40))
    watcher.join()
    kept = len(list(store.root.rglob("*.pkl")))
    assert 1 <= kept < 40  # the parts done before the cancel are kept
    again = CachedMap(map, tmp_path / "store")  # and read back by the next attempt
    out = again(fn, _parts(40))
    assert (again.hits, again.misses) == (kept, 40 - kept)
    assert all(o.tobytes() == np.square(p).tobytes() for o, p in zip(out, _parts(40)))
