"""graphloc.executor and graphloc.many_runs (issue 19): results in item order whatever the
backend and worker count, a failing task reported while the others finish, the content-hash
cache, many runs through `graphloc smooth`; and (slow, needs Ray) a local Ray
instance with 2 CPUs giving the same numbers as the local pool on a small sweep of simulated
runs and quick reproductions."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.trials import TaskFailed, TrialExecutor, default_backend
from graphloc.cli import main
from graphloc.executor import Executor, ResultCache, _probe, content_hash


def _noisy_sum(item: tuple[int, int]) -> float:
    """A seeded trial: fails for index 3."""
    index, seed = item
    if index == 3:
        raise ValueError(f"trial {index} cannot be solved")
    return float(np.random.default_rng(seed).normal(size=100).sum())


def _square(x: int) -> int:
    return x * x


def _items(n: int = 6) -> list[tuple[int, int]]:
    return [(i, 7000 + i) for i in range(n)]


@pytest.mark.parametrize("workers", [1, 2])
def test_map_keeps_item_order_reports_failures_and_caches(tmp_path, workers):
    items = _items()
    expected = [_noisy_sum(it) if it[0] != 3 else None for it in items]
    cache = ResultCache(tmp_path / "cache")
    hashes = [content_hash([], {"item": it}) for it in items]
    with Executor(workers, progress=False) as ex:
        first = ex.map(
            _noisy_sum, items, keys=[f"t{i}" for i, _ in items], cache=cache, hashes=hashes
        )
        again = ex.map(_noisy_sum, items, cache=cache, hashes=hashes)
    assert [o.value for o in first] == expected
    assert [o.key for o in first] == [f"t{i}" for i in range(6)]
    assert not first[3].ok and "ValueError: trial 3 cannot be solved" in first[3].error
    assert all(o.ok and not o.cached for i, o in enumerate(first) if i != 3)
    # the re-run reads the five finished tasks back and retries the failed one
    assert [o.cached for o in again] == [True, True, True, False, True, True]
    assert [o.value for o in again] == expected and not again[3].ok


def test_imap_keeps_item_order_and_raises_naming_the_task():
    with TrialExecutor(2, progress=False) as ex:
        with pytest.raises(TaskFailed, match=r"task 3 \(\(3, .*ValueError: trial 3"):
            list(ex.imap(_noisy_sum, _items()))
        two = list(ex.imap(_square, range(5)))
    with TrialExecutor(1, progress=False) as ex:
        one = list(ex.imap(_square, range(5)))
    assert two == one == [x * x for x in range(5)]


def test_hashes_and_options_are_checked(tmp_path):
    f = tmp_path / "run" / "a.csv"
    f.parent.mkdir()
    f.write_text("1,2\n")
    h = content_hash([f.parent], {"lag": 5})
    assert h == content_hash([f.parent], {"lag": 5}) != content_hash([f.parent], {"lag": 6})
    f.write_text("1,3\n")
    assert content_hash([f.parent], {"lag": 5}) != h
    with pytest.raises(ValueError, match="--backend must be one of local, ray"):
        Executor(1, "dask")
    with pytest.raises(ValueError, match="--workers must be an integer >= 1"):
        Executor(0)
    with pytest.raises(ValueError, match="--address needs --backend ray"):
        Executor(1, "local", address="auto")
    # a cluster address that does not answer is an error at once (Ray would retry for minutes)
    with pytest.raises(ValueError, match="127.0.0.1:1: no Ray cluster answers there"):
        _probe("127.0.0.1:1", timeout=2.0)
    with pytest.raises(ValueError, match="expected 'auto' or HOST:PORT"):
        _probe("head-node")


def _simulate(root: Path, seeds) -> list[str]:
    runs = []
    for s in seeds:
        run = root / f"feng{s}"
        args = ["simulate", "feng-probabilistic", "--out", str(run), "--seed", str(s)]
        assert main(args) == 0
        runs.append(str(run))
    return runs


def _rows(out: Path) -> dict:
    """runs.json rows without what depends on the machine (wall times) or on the cache."""
    rows = json.loads((out / "runs.json").read_text())["runs"]
    drop = ("seconds", "realtime_factor", "status", "path")
    return {r["run"]: {k: v for k, v in r.items() if k not in drop} for r in rows}


def test_smooth_over_many_runs_failure_cache_and_report(tmp_path, capsys):
    (run,) = _simulate(tmp_path, [1])
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "manifest.json").write_text("{")
    listing = tmp_path / "runs.txt"
    listing.write_text(f"# a team's day\n{run}\nbad\n")
    out = tmp_path / "out"
    args = ["smooth", "--runs", str(listing), "--out", str(out), "--workers", "2", "--no-progress"]
    args += ["--duration", "15"]
    assert main(args) == 4  # one run failed, the other finished
    with open(out / "runs.csv") as fh:
        rows = {r["run"]: r for r in csv.DictReader(fh)}
    assert rows["feng1"]["status"] == "ok" and rows["feng1"]["ate_rmse_m"].startswith("climber=")
    assert rows["bad"]["status"] == "failed" and "manifest.json" in rows["bad"]["error"]
    assert (out / "feng1" / "metrics.json").is_file() and (out / "runs_summary.png").is_file()
    assert "| feng1 | ok |" in (out / "runs.md").read_text()
    first = _rows(out)
    assert main(args) == 4
    again = json.loads((out / "runs.json").read_text())["runs"]
    assert [r["status"] for r in again] == ["cached", "failed"] and _rows(out) == first
    assert "failed" in capsys.readouterr().err
    assert main(["smooth", "--runs", str(tmp_path / "none.txt"), "--out", str(out)]) == 2


@pytest.mark.slow
def test_ray_and_local_backends_give_identical_numbers(tmp_path):
    """A local Ray instance with 2 CPUs; the same small sweep on Ray and on the local pool:
    three short simulated runs (and a bad one) through `graphloc smooth` and `online`, and the
    quick reproductions of seed 000 Table I and seed 004 Table 1."""
    ray = pytest.importorskip("ray", reason="the Ray backend needs graphloc[ray]")
    from benchmarks.reproduce import main as reproduce_main
    from benchmarks.reproduce import reproduce

    runs = _simulate(tmp_path, [1, 2, 3])
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "manifest.json").write_text("{")
    runs.append(str(tmp_path / "bad"))

    def strip(d):  # timings are not results
        if isinstance(d, dict):
            return {
                k: strip(v)
                for k, v in d.items()
                if k not in ("timing", "wall_time_s") and "latency" not in k
            }
        return [strip(v) for v in d] if isinstance(d, list) else d

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        results = {}
        for backend in ("local", "ray"):
            for verb in ("smooth", "online"):
                out = tmp_path / f"{verb}_{backend}"
                common = ["--out", str(out), "--workers", "2", "--no-progress", "--duration", "15"]
                assert main([verb, *runs, *common, "--backend", backend]) == 4
                tum = {
                    p.relative_to(out).as_posix(): p.read_text() for p in sorted(out.rglob("*.tum"))
                }
                results[backend, verb] = (_rows(out), tum)
            with default_backend(backend, workers=2):
                for table in ("seed000-table1", "seed004-table1"):
                    r, cached = reproduce(table, True, 2, tmp_path / f"rep_{backend}", False)
                    assert not cached
                    results[backend, table] = strip(r)
        # scripts/reproduce.py --backend ray, then the same table from its cache
        rep = tmp_path / "rep_script"
        argv = ["seed004-table1", "--quick", "--out", str(rep), "--backend", "ray"]
        assert reproduce_main(argv) == 0 and reproduce_main(argv) == 0
        assert (rep / ".cache").is_dir()
        table = json.loads((rep / "seed004-table1.json").read_text())
        assert strip(table) == results["local", "seed004-table1"]
        assert ray.is_initialized()  # the executor reused the test's instance, left it running
    finally:
        ray.shutdown()
    for key in [k for k in results if k[0] == "local"]:
        assert results["ray", key[1]] == results[key], key[1]
    rows, tum = results["local", "smooth"]
    assert len(tum) >= 9 and "error" in rows["bad"] and rows["feng2"]["ate_rmse_m"]


POOL_SCRIPT = """
from tqdm import tqdm
from graphloc.executor import Executor


def task(x):
    for _ in tqdm(range(2), disable=True):  # a bar in the worker, as the pipelines make
        pass
    return x * x


if __name__ == "__main__":
    with Executor(2, progress=False) as ex:
        print([o.value for o in ex.map(task, [1, 2, 3])])
"""


def test_pool_workers_leave_no_semaphore_behind(tmp_path):
    """Workers start from the fork server and are ended without finalizers: a multiprocessing
    lock tqdm made in one would be reported as leaked when the command exits."""
    import subprocess
    import sys

    script = tmp_path / "pool.py"
    script.write_text(POOL_SCRIPT)
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=tmp_path
    )
    assert done.returncode == 0 and done.stdout.strip() == "[1, 4, 9]", done.stderr
    assert "leaked" not in done.stderr, done.stderr
