"""The shared job pool: results in job order, jobs on other processes, one thread per job."""

import os

import pytest

from app.learning.jobs import JobPool


def where_and_threads(index: int) -> tuple[int, int, int, set[int]]:
    """(index, process id, torch threads, every BLAS/OpenMP pool's threads) inside a job."""
    import torch
    from threadpoolctl import threadpool_info

    pools = {p["num_threads"] for p in threadpool_info()}
    return index, os.getpid(), torch.get_num_threads(), pools


@pytest.mark.parametrize("workers", [1, 2])
def test_jobs_come_back_in_order_each_on_one_thread(workers):
    jobs = [(i,) for i in range(5)]
    with JobPool(workers) as pool:
        out = pool.run(where_and_threads, jobs, "test jobs", "job")
    assert [row[0] for row in out] == list(range(5))
    assert all(row[2] == 1 and row[3] == {1} for row in out)
    here = {row[1] for row in out} == {os.getpid()}
    assert here == (workers == 1), "one worker runs in this process, two elsewhere"


def test_a_failing_job_raises_and_no_pool_is_needed_for_none():
    with JobPool(2) as pool:
        assert pool.run(where_and_threads, [], "nothing", "job") == []
        with pytest.raises(TypeError):
            pool.run(where_and_threads, [(1,), (2, 3)], "bad", "job")
    with pytest.raises(ValueError, match="at least 1"):
        JobPool(0)
