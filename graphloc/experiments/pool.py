"""The one way the experiments spread trials over processes: `worker_pool(workers)` is a
multiprocessing.Pool for workers > 1 and an in-process stand-in for one worker (no process
start-up, same results: every trial seeds its own generator)."""

from __future__ import annotations

import multiprocessing as mp


class _Serial:
    """Stand-in for multiprocessing.Pool with one worker."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    @staticmethod
    def imap(fn, jobs):
        return map(fn, jobs)

    imap_unordered = imap


def worker_pool(workers: int):
    """A context manager with `imap` / `imap_unordered` over `workers` processes."""
    if workers < 1:
        raise ValueError(f"worker_pool: workers must be >= 1, got {workers}")
    return mp.Pool(workers) if workers > 1 else _Serial()
