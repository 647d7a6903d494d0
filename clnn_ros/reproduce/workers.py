"""Jobs run in worker processes, for the commands whose seeds run one by one in Python (the
field's agents of `versus`, `learn --task`): their results as they finish, and Ctrl-C ending
them all at once."""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import signal
from typing import Callable, Iterable, Iterator


def in_workers(function: Callable, jobs: Iterable[tuple], workers: int) -> Iterator[tuple]:
    """(job, function(*job)) for every job, in the order they finish, computed by `workers`
    spawned processes. Ctrl-C reaches the terminal's whole process group: the workers start
    with SIGINT blocked (a child inherits the mask), so that this process alone takes it and
    ends them at once (a seed may take minutes); whatever the caller kept of the results
    before stays."""
    jobs = list(jobs)
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        pool = concurrent.futures.ProcessPoolExecutor(
            workers, mp_context=multiprocessing.get_context("spawn"))
        futures = {pool.submit(function, *job): job for job in jobs}
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    try:
        for future in concurrent.futures.as_completed(futures):
            yield futures[future], future.result()
    except BaseException:
        for worker in multiprocessing.active_children():
            worker.terminate()
        raise
    finally:
        pool.shutdown(cancel_futures=True)
