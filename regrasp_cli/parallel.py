"""Process parallelism for the offline builds and the online stages.

The workers are forked after the caller has built its (large, unpicklable) context —
robot model, collision worlds, surface model, passed as ``context``, which each call
receives as its first argument — so they inherit it instead of rebuilding it, and results
come back in order, so a result is the same whatever the number of jobs.
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


_RUNNING: list = [None]  # (fn, context) of the running map, inherited by the forked workers


def _call(item):
    fn, context = _RUNNING[0]
    return fn(context, item)


def ordered_map(fn: Callable[[Any, T], R], items: Iterable[T], jobs: int, context: Any = None) -> Iterator[R]:
    """``fn(context, item)`` for each item, over ``jobs`` forked processes (in this process
    when jobs <= 1), in order.  ``context`` may be anything, unpicklable included: the
    workers inherit it (and ``fn``) at the fork; only items and results are pickled.  With
    jobs > 1, not for use from several threads at once.  Stopping the iteration early terminates the
    workers."""
    items = list(items)
    if jobs <= 1 or len(items) <= 1:  # no shared state: threads may each run a map in this process
        yield from (fn(context, item) for item in items)
        return
    previous, _RUNNING[0] = _RUNNING[0], (fn, context)
    try:
        pool = multiprocessing.get_context("fork").Pool(min(jobs, len(items)))
        try:
            yield from pool.imap(_call, items)
        finally:
            pool.terminate()
            pool.join()
    finally:
        _RUNNING[0] = previous


class Workers:
    """Forked workers for work whose next items depend on the results so far: ``submit``
    one item at a time, ask for its result when it is needed.  The context is inherited
    at the fork, as with :func:`ordered_map`; with jobs <= 1 an item runs in this process
    when its result is asked for, so a caller that decides what to submit only from the
    results it has asked for gets the same results whatever the number of jobs."""

    def __init__(self, fn: Callable[[Any, T], R], jobs: int, context: Any = None):
        self.fn, self.jobs, self.context, self.pool, self.previous = fn, jobs, context, None, None

    def __enter__(self) -> "Workers":
        if self.jobs > 1:
            self.previous, _RUNNING[0] = _RUNNING[0], (self.fn, self.context)
            self.pool = multiprocessing.get_context("fork").Pool(self.jobs)
        return self

    def submit(self, item: T) -> Callable[[], R]:
        """Start ``fn(context, item)``; returns the call that waits for its result."""
        if self.pool is None:
            return lambda: self.fn(self.context, item)
        return self.pool.apply_async(_call, (item,)).get

    def __exit__(self, *exc) -> None:
        if self.pool is not None:
            self.pool.terminate()
            self.pool.join()
            _RUNNING[0] = self.previous
