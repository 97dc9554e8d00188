"""Fitting a unit of a twin table: the fits shared among forked processes."""

from __future__ import annotations

import multiprocessing
import os

from dtwin.gap.table_fit import map_fits


def test_map_fits_returns_each_call_s_result_in_order_from_forked_workers():
    offset = 3  # a closure: the workers are forks of this process
    results = map_fits(lambda i: (i + offset, os.getpid()), range(6))
    assert [value for value, _ in results] == [3, 4, 5, 6, 7, 8]
    forks = "fork" in multiprocessing.get_all_start_methods()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if forks and cores >= 2:
        assert all(pid != os.getpid() for _, pid in results)


def test_map_fits_inside_a_worker_runs_its_calls_in_turn():
    def inner(i):
        return sorted({pid for pid in map_fits(lambda _: os.getpid(), range(3))}), os.getpid()

    for pids, worker in map_fits(inner, range(2)):
        assert pids == [worker]  # no pool of pools


def _pids_in_a_user_pool(_item):
    return sorted({pid for pid in map_fits(lambda _: os.getpid(), range(3))}), os.getpid()


def test_map_fits_inside_a_user_s_pool_worker_runs_its_calls_in_turn():
    """A user's multiprocessing.Pool worker is daemonic and may not start processes."""
    if "fork" not in multiprocessing.get_all_start_methods():
        return
    with multiprocessing.get_context("fork").Pool(1) as pool:
        ((pids, worker),) = pool.map(_pids_in_a_user_pool, [0])
    assert pids == [worker]
