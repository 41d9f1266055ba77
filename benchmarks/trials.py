"""The benchmarks' trials on `graphloc.executor`: `TrialExecutor.imap` (values in item order, a
failed trial raising `TaskFailed`) and `default_backend`, the backend a block of benchmarks
runs on."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator

from graphloc.executor import Executor

# the backend a TrialExecutor created without one uses (`default_backend` sets it for a block)
_DEFAULT = {"backend": "local", "address": None}


class TaskFailed(RuntimeError):
    """A task of `TrialExecutor.imap` raised; the message names the task and its error."""


class TrialExecutor(Executor):
    """An `Executor` whose backend defaults to the block's (`default_backend`), with `imap`."""

    def __init__(self, workers: int = 1, backend: str | None = None, address=None, progress=True):
        if backend is None:
            backend, address = _DEFAULT["backend"], address or _DEFAULT["address"]
        super().__init__(workers, backend, address, progress)

    def imap(self, fn: Callable, items: Iterable, *, desc: str = "tasks") -> Iterator:
        """The values of fn over items, in item order, as they become available in that order;
        a failed task raises TaskFailed (trials of an experiment: a failure is a bug)."""
        items = list(items)
        from tqdm import tqdm

        bar = tqdm(total=len(items), desc=desc, disable=not self.progress, leave=False)
        ready: dict[int, tuple] = {}
        nxt = 0
        for i, result in self._run(fn, items, list(range(len(items)))):
            ready[i] = result
            bar.update(1)
            while nxt in ready:
                status, value, _ = ready.pop(nxt)
                if status != "ok":
                    bar.close()
                    raise TaskFailed(f"{desc}: task {nxt} ({_short(items[nxt])}) failed: {value}")
                yield value
                nxt += 1
        bar.close()


def _short(item) -> str:
    text = repr(item)
    return text if len(text) <= 120 else text[:117] + "..."


@contextlib.contextmanager
def default_backend(backend: str = "local", address: str | None = None, workers: int = 1):
    """Within the block, a `TrialExecutor` created without a backend uses this one; a Ray
    instance is started once for the whole block and shut down at its end."""
    with Executor(workers, backend, address, progress=False):
        old = dict(_DEFAULT)
        _DEFAULT.update(backend=backend, address=address)
        try:
            yield
        finally:
            _DEFAULT.update(old)
