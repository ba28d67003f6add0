"""Run independent jobs on several processes with one progress bar, with the results of one.

A job is a module-level function and its arguments (both are pickled to a spawn process).
Every job runs with torch, BLAS and OpenMP on one thread each, in a worker or in this process:
two workers then do not fight over two cores (with a second BLAS thread on a busy 2-core
machine, a scikit-learn MLP fit ran 8-19 times slower), and a job computes what it computes
in this process, whichever worker runs it.
"""

import multiprocessing as mp
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager

from tqdm import tqdm


class JobPool:
    """`workers` spawn processes, started on first use and kept for every `run`; with one
    worker the jobs run one after another in this process."""

    def __init__(self, workers: int):
        if workers < 1:
            raise ValueError(f"workers must be at least 1, not {workers}")
        self.workers = workers
        self._pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> "JobPool":
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def run(self, fn: Callable, jobs: list[tuple], desc: str, unit: str,
            postfix: Callable[[object], dict] | None = None) -> list:
        """fn(*job) for every job, results in job order; the bar advances as each job
        finishes, whichever process ran it (`postfix(result)` sets its postfix)."""
        results: list = [None] * len(jobs)
        with tqdm(total=len(jobs), desc=desc, unit=unit, disable=not jobs) as bar:
            for index, result in self._finished(fn, jobs):
                results[index] = result
                if postfix is not None:
                    bar.set_postfix(postfix(result), refresh=False)
                bar.update(1)
        return results

    def _finished(self, fn: Callable, jobs: list[tuple]) -> Iterator[tuple[int, object]]:
        """(job index, result) as each job finishes; a job's error is raised here."""
        if self.workers == 1 or len(jobs) <= 1:
            for index, job in enumerate(jobs):
                yield index, one_thread_each(fn, job)
            return
        pool = self._executor()
        futures = {pool.submit(one_thread_each, fn, job): index for index, job in enumerate(jobs)}
        for done in as_completed(futures):
            yield futures[done], done.result()

    def _executor(self) -> ProcessPoolExecutor:
        if self._pool is None:
            # spawn, not fork: a forked child of a process that has run torch can deadlock
            self._pool = ProcessPoolExecutor(self.workers, mp_context=mp.get_context("spawn"))
        return self._pool


@contextmanager
def job_pool(workers: "int | JobPool") -> Iterator[JobPool]:
    """`workers` itself when it is a pool (its owner closes it: several phases share its
    started workers), else a pool of that many workers for the block."""
    if isinstance(workers, JobPool):
        yield workers
        return
    with JobPool(workers) as pool:
        yield pool


def one_thread_each(fn: Callable, job: tuple):
    """fn(*job) with torch's intra-op threads, BLAS and OpenMP each limited to one thread."""
    from threadpoolctl import threadpool_limits

    from app.learning.train import one_thread  # loads torch, numpy, scipy and scikit-learn

    # threadpool_limits reaches only loaded libraries: all four are, by the import above
    with one_thread(), threadpool_limits(limits=1):
        return fn(*job)
