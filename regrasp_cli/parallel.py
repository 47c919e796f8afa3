"""Process parallelism for the offline builds.

The workers are forked after the caller has built its (large, unpicklable) context —
robot model, collision worlds, surface model — so they inherit it instead of rebuilding
it, and results come back in order, so a build is the same whatever the number of jobs.
Only the work items and the results cross process boundaries.
"""

from __future__ import annotations

import multiprocessing
from typing import Callable, Iterable, Iterator, TypeVar

T = TypeVar("T")
R = TypeVar("R")


def ordered_map(fn: Callable[[T], R], items: Iterable[T], jobs: int) -> Iterator[R]:
    """``map(fn, items)`` over ``jobs`` forked processes (in this process when jobs <= 1),
    in order.  ``fn`` must be a module-level function.  Stopping the iteration early
    terminates the workers."""
    if jobs <= 1:
        yield from map(fn, items)
        return
    pool = multiprocessing.get_context("fork").Pool(jobs)
    try:
        yield from pool.imap(fn, items)
    finally:
        pool.terminate()
        pool.join()
