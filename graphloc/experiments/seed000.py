"""Reproduce seed 000 (/work/shared/seeds/000_05137a0a9c449be3.txt) Tables I, II, III and a
Fig. 6 style plot, paper | seed baseline (ours) | graphloc on the same trials
(library code: graphloc.tables).

    .venv/bin/python scripts/repro_seed000.py [--quick] [--trials 1000 --runs 100] --out out/seed000

Writes <out>/seed000.json, <out>/seed000.md, <out>/table1_errors.png, <out>/table3_convergence.png,
<out>/fig6_posterior.png and prints the markdown tables.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from graphloc import tables  # noqa: E402


def plot_table_i(r: dict, path: Path) -> None:
    fig, ax = plt.subplots(figsize=(6.5, 4))
    labels = ["C2", "C3", "C"]
    x = np.arange(3)
    for i, (key, name) in enumerate((("seed_baseline", "seed baseline (ours)"), ("graphloc", "graphloc"))):
        ax.bar(x + (i - 0.5) * 0.27, [r[key][c]["mean"] or np.nan for c in labels], 0.27, label=name,
               yerr=[r[key][c]["std"] or 0 for c in labels])
    ax.bar(x + 0.27 * 1.5, [r["paper"][c][0] for c in labels], 0.27, label="paper")
    ax.set_xticks(x, labels)
    ax.set_yscale("log")
    ax.set_ylabel("relative position error")
    ax.set_title(f"Seed 000 Table I: success {r['seed_baseline']['success']} vs {r['graphloc']['success']} / {r['trials']}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_table_iii(r: dict, path: Path) -> None:
    names = list(r["cells"])
    series = [("paper", [r["cells"][n]["paper_table_iii"] for n in names])]
    for m in ("belief_def1", "belief_def2", "particle_filter", "tracker"):
        series.append((m, [r["cells"][n][m]["mean_updates_to_converge"] or np.nan for n in names]))
    fig, ax = plt.subplots(figsize=(9, 4))
    w = 0.8 / len(series)
    for i, (label, values) in enumerate(series):
        ax.bar(np.arange(len(names)) + (i - len(series) / 2 + 0.5) * w, values, w, label=label)
    ax.set_xticks(np.arange(len(names)), names, fontsize=8)
    ax.set_ylabel("mean updates to converge")
    ax.set_title("Seed 000 Table III")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_fig6(series: dict, path: Path) -> None:
    fig, axes = plt.subplots(2, 3, figsize=(11, 5.5), sharey=True)
    for ax, (name, s) in zip(axes.T.ravel(), series.items()):
        for method, style in (("belief_def1", "o-"), ("tracker", "s-")):
            ax.plot(np.arange(len(s[method])), s[method], style, ms=3, label=method)
        ax.axhline(0.95, color="k", ls="--", lw=0.8)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("update")
    axes[0, 0].set_ylabel("P(genuine candidate)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Seed 000 Fig. 6 style: posterior of the genuine candidate")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(out: Path, trials: int, runs: int, workers: int, progress: bool = True) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    t1 = tables.table_i(tables.TableIConfig(trials=trials, workers=workers), progress)
    t3 = tables.table_iii(tables.TableIIIConfig(runs=runs, workers=workers), progress)
    t2 = tables.table_ii(t3, samples=min(100, trials), table1=t1)
    f6 = tables.fig6_series()
    result = {"table_i": t1, "table_ii": t2, "table_iii": t3, "fig6": f6, "wall_time_s": time.perf_counter() - t0}
    md = "\n".join([tables.markdown_table_i(t1), tables.markdown_table_ii(t2), tables.markdown_table_iii(t3),
                    "Fig. 6 style plot: fig6_posterior.png; Table I errors: table1_errors.png; Table III: table3_convergence.png.\n"])
    (out / "seed000.json").write_text(json.dumps(result, indent=2, default=float))
    (out / "seed000.md").write_text(md)
    plot_table_i(t1, out / "table1_errors.png")
    plot_table_iii(t3, out / "table3_convergence.png")
    plot_fig6(f6, out / "fig6_posterior.png")
    result["markdown"] = md
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=1000, help="Table I trials (paper: 1000)")
    parser.add_argument("--runs", type=int, default=100, help="Table III runs per cell (paper: 100)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="CI size: 100 trials, 5 runs per cell")
    parser.add_argument("--out", type=Path, default=Path("out/seed000"))
    args = parser.parse_args(argv)
    if args.quick:
        args.trials, args.runs = min(args.trials, 100), min(args.runs, 5)
    print(run(args.out, args.trials, args.runs, args.workers)["markdown"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
