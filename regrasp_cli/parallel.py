"""Process parallelism for the offline builds and the online stages.

The workers are forked after the caller has built its (large, unpicklable) context —
robot model, collision worlds, surface model, passed as ``context`` and read with
:func:`shared` — so they inherit it instead of rebuilding it, and results come back in
order, so a result is the same whatever the number of jobs.
Only the work items and the results cross process boundaries.

joblib (its ``multiprocessing`` backend, the one that forks, used as a context manager in
waves) was measured side by side: the grasp search took 6.0 s instead of 3.8 s (statuette)
and 9.3 s instead of 7.6 s (horse), because every wave waits for its slowest item and
joblib cannot stream results from that backend.  A multiprocessing pool's ordered
``imap`` streams them.  Scaling out to a cluster (a later issue) will need its own path.
"""

from __future__ import annotations

import multiprocessing
from typing import Any, Callable, Iterable, Iterator, TypeVar

T = TypeVar("T")
R = TypeVar("R")


_SHARED: list = [None]  # the context of the running map, inherited by the forked workers


def shared() -> Any:
    """The ``context`` given to the :func:`ordered_map` that is running ``fn``."""
    return _SHARED[0]


def ordered_map(fn: Callable[[T], R], items: Iterable[T], jobs: int, context: Any = None) -> Iterator[R]:
    """``map(fn, items)`` over ``jobs`` forked processes (in this process when jobs <= 1),
    in order.  ``fn`` must be a module-level function; it reads ``context`` (anything,
    unpicklable included: the workers inherit it) with :func:`shared`.  Not for use from
    several threads at once.  Stopping the iteration early terminates the workers."""
    items = list(items)
    previous, _SHARED[0] = _SHARED[0], context
    try:
        if jobs <= 1 or len(items) <= 1:
            yield from map(fn, items)
            return
        pool = multiprocessing.get_context("fork").Pool(min(jobs, len(items)))
        try:
            yield from pool.imap(fn, items)
        finally:
            pool.terminate()
            pool.join()
    finally:
        _SHARED[0] = previous
