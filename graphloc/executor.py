"""Runs the tasks of many runs or trials on a local process pool or on Ray, with a result cache
keyed by content hash; results come back in item order whatever the backend
(docs/design_core.md, "Executor")."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import multiprocessing as mp
import socket
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from graphloc import __version__
from graphloc.names import written_whole
from graphloc.structured import MAX_DATA_BYTES, dumps_json, read_json

BACKENDS = ("local", "ray")


@dataclass(frozen=True)
class Outcome:
    """One task's end: `value` (None on failure), `error` ("Type: message", None on success),
    `cached` (read from the ResultCache, not computed), `seconds` (the task's own wall time;
    0 when cached)."""

    key: str
    value: Any
    error: str | None
    cached: bool
    seconds: float

    @property
    def ok(self) -> bool:
        return self.error is None


@lru_cache(maxsize=1)
def code_version() -> str:
    """graphloc's version plus a SHA-256 of its installed sources (graphloc, graphloc.factors,
    graphloc.datasets), so that a cached result never outlives a change of the code."""
    h = hashlib.sha256(__version__.encode())
    for package in ("graphloc", "graphloc.factors", "graphloc.datasets"):
        root = Path(importlib.util.find_spec(package).origin).parent
        for path in sorted(root.rglob("*.py")):
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
    return f"{__version__}+{h.hexdigest()[:16]}"


def _hash_path(h, path: Path) -> None:
    """Names and bytes of a file, or of every file under a directory (sorted)."""
    if path.is_dir():
        files = sorted(p for p in path.rglob("*") if p.is_file())
    elif path.is_file():
        files = [path]
    else:
        raise FileNotFoundError(f"{path}: no such file or directory")
    for f in files:
        h.update(str(f.relative_to(path) if f != path else f.name).encode())
        with open(f, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)


def content_hash(inputs: Iterable[Path] = (), config: Any = None) -> str:
    """SHA-256 of the input files' contents (directories recursively), the configuration (any
    JSON-able value) and `code_version()`: the key of a task's cached result."""
    h = hashlib.sha256(code_version().encode())
    for path in inputs:
        _hash_path(h, Path(path))
    h.update(json.dumps(config, sort_keys=True, default=str).encode())
    return h.hexdigest()


class ResultCache:
    """JSON results under `directory`, one file per content hash, written atomically."""

    def __init__(self, directory: Path):
        self.directory = Path(directory)

    def _path(self, digest: str) -> Path:
        return self.directory / f"{digest}.json"

    def get(self, digest: str):
        """The cached value, or None (absent or unreadable: then it is recomputed)."""
        path = self._path(digest)
        try:
            if not path.is_file():
                return None
            return read_json(path, "cached result", max_bytes=MAX_DATA_BYTES)["value"]
        except (OSError, ValueError, KeyError, TypeError):
            return None

    def discard(self, digest: str) -> None:
        self._path(digest).unlink(missing_ok=True)

    def put(self, digest: str, value) -> None:
        self.directory.mkdir(parents=True, exist_ok=True)
        with written_whole(self._path(digest)) as tmp:
            tmp.write_text(dumps_json({"version": code_version(), "value": value}, default=float))


def _init_worker() -> None:
    """A pool worker's start: tqdm's lock as a thread lock (a multiprocessing lock, made on its
    first bar, is never released by a pool worker: the resource tracker would warn of a leak)."""
    from tqdm import tqdm

    tqdm.set_lock(threading.RLock())


def _call(fn: Callable, item):
    """Run one task and return ("ok", value, seconds) or ("error", message, seconds)."""
    t0 = time.perf_counter()
    try:
        return "ok", fn(item), time.perf_counter() - t0
    except Exception as exc:  # reported per task; the other tasks go on
        where = traceback.extract_tb(exc.__traceback__)[-1]
        message = f"{type(exc).__name__}: {exc} ({Path(where.filename).name}:{where.lineno})"
        return "error", message, time.perf_counter() - t0


class Executor:
    """Runs tasks on the local pool ("forkserver") or Ray, as a context manager: the pool or a Ray
    instance it started lives for the `with` block (a running Ray instance is reused);
    `address`: "auto" or "HOST:PORT" of a Ray cluster."""

    def __init__(
        self,
        workers: int = 1,
        backend: str = "local",
        address: str | None = None,
        progress: bool = True,
    ):
        if backend not in BACKENDS:
            raise ValueError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        if not (isinstance(workers, int) and workers >= 1):
            raise ValueError(f"--workers must be an integer >= 1, got {workers!r}")
        if address is not None and backend != "ray":
            raise ValueError("--address needs --backend ray")
        self.workers, self.backend, self.address = workers, backend, address
        self.progress = progress
        self._ray, self._started_ray = None, False

    def __enter__(self) -> Executor:
        if self.backend == "ray":
            self._ray, self._started_ray = _start_ray(self.workers, self.address)
        return self

    def __exit__(self, *exc) -> bool:
        if self._started_ray:
            self._ray.shutdown()
        self._ray, self._started_ray = None, False
        return False

    # ---- the two ways to run tasks ----------------------------------------------------------
    def map(
        self,
        fn: Callable,
        items: list,
        *,
        keys: list[str] | None = None,
        cache: ResultCache | None = None,
        hashes: list[str] | None = None,
        desc: str = "tasks",
    ) -> list[Outcome]:
        """Every item's Outcome, in item order. With `cache` and `hashes` (one content hash per
        item), cached items are not run and successful results are stored (JSON values)."""
        items = list(items)
        keys = [str(i) for i in range(len(items))] if keys is None else [str(k) for k in keys]
        if len(keys) != len(items) or (hashes is not None and len(hashes) != len(items)):
            raise ValueError("Executor.map: keys / hashes must have one entry per item")
        if cache is not None and hashes is None:
            raise ValueError("Executor.map: a cache needs a content hash per item")
        outcomes: list[Outcome | None] = [None] * len(items)
        todo = []
        for i in range(len(items)):
            hit = cache.get(hashes[i]) if cache is not None else None
            if hit is not None:
                outcomes[i] = Outcome(keys[i], hit, None, True, 0.0)
            else:
                todo.append(i)
        counts = {"done": 0, "failed": 0, "cached": len(items) - len(todo)}
        from tqdm import tqdm

        bar = tqdm(total=len(items), desc=desc, disable=not self.progress, leave=False)
        bar.update(counts["cached"])
        bar.set_postfix(counts)
        for i, (status, value, seconds) in self._run(fn, [items[i] for i in todo], todo):
            ok = status == "ok"
            if ok and cache is not None:  # computed and cached results look the same
                value = json.loads(json.dumps(value, default=float))
            outcomes[i] = Outcome(
                keys[i], value if ok else None, None if ok else value, False, seconds
            )
            if ok and cache is not None:
                cache.put(hashes[i], value)
            counts["done" if ok else "failed"] += 1
            bar.update(1)
            bar.set_postfix(counts)
        bar.close()
        return outcomes

    # ---- backends ---------------------------------------------------------------------------
    def _run(self, fn, items: list, index: list[int]) -> Iterator[tuple[int, tuple]]:
        """(index, (status, value, seconds)) per item, in completion order."""
        if not items:
            return
        if self.backend == "ray":
            yield from self._run_ray(fn, items, index)
        elif self.workers == 1 or len(items) == 1:
            for i, item in zip(index, items):
                yield i, _call(fn, item)
        else:
            ctx = mp.get_context("forkserver")  # not "fork": see docs/design_core.md
            with ctx.Pool(min(self.workers, len(items)), _init_worker) as pool:
                jobs = [(pos, fn, item) for pos, item in enumerate(items)]
                for pos, result in pool.imap_unordered(_indexed, jobs):
                    yield index[pos], result

    def _run_ray(self, fn, items: list, index: list[int]):
        ray = self._ray
        if ray is None:
            raise RuntimeError("Executor(backend='ray') must be used in a `with` block")
        remote = ray.remote(num_cpus=1, max_retries=0)(_call)
        # `workers` tasks in flight (a local instance started here has that many CPUs too)
        limit = self.workers
        pending: dict = {}
        nxt = 0
        while nxt < len(items) or pending:
            while nxt < len(items) and len(pending) < limit:
                pending[remote.remote(fn, items[nxt])] = index[nxt]
                nxt += 1
            done, _ = ray.wait(list(pending), num_returns=1)
            for obj in done:
                try:
                    result = ray.get(obj)
                except Exception as exc:  # the worker died (a crash in native code, OOM kill)
                    result = ("error", f"{type(exc).__name__}: {exc}", 0.0)
                yield pending.pop(obj), result


def _indexed(job):
    pos, fn, item = job
    return pos, _call(fn, item)


def _start_ray(workers: int, address: str | None):
    """(the ray module, whether this call started the instance)."""
    try:
        import ray
    except ImportError:
        raise ValueError(
            "--backend ray needs Ray: pip install 'graphloc[ray]' (or pip install ray)"
        ) from None
    if ray.is_initialized():
        return ray, False
    kwargs = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
    if address is None:
        ray.init(num_cpus=workers, **kwargs)
    else:
        if address != "auto":
            _probe(address)
        try:
            ray.init(address=address, **kwargs)
        except ConnectionError as exc:
            raise ValueError(f"--address {address}: cannot connect to a Ray cluster: {exc}")
    return ray, True


def _probe(address: str, timeout: float = 5.0) -> None:
    """HOST:PORT answers a TCP connection within `timeout` s (Ray itself retries for minutes)."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"--address {address!r}: expected 'auto' or HOST:PORT")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as exc:
        raise ValueError(f"--address {address}: no Ray cluster answers there ({exc})") from None
