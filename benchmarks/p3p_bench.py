"""P3P ground truth and benchmark: random well-conditioned instances, the recovery criterion
shared by every solver, and a timed comparison of the batched graphloc solvers against
per-instance Python loops over cv2.solveP3P (P3P, AP3P) and poselib.p3p on the same instances.
Run by scripts/bench_p3p.py (`main`, `make bench-p3p`); the instances and the criterion are
used by tests/vision/test_p3p.py."""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from benchmarks.baselines.p3p_seeds import METHODS, solve_p3p_by_name
from graphloc.geometry.p3p import MAX_CANDIDATES
from graphloc.plots import plt
from graphloc.structured import dumps_json

RECOVERY_TOL = 1e-6  # rotation (Frobenius of R - R_true) and translation [m] errors


@dataclass(frozen=True)
class P3PInstances:
    """N P3P problems with their truth. bearings, points (N,3,3); R_wc (N,3,3), t_wc (N,3);
    depths (N,3) along the bearings."""

    bearings: np.ndarray
    points: np.ndarray
    R_wc: np.ndarray
    t_wc: np.ndarray
    depths: np.ndarray


@dataclass(frozen=True)
class InstanceConfig:
    """Random camera in a [-box, box]^3 cube, three points within `half_fov` of the optical axis
    (+z) at depths in [min_depth, max_depth]; instances are redrawn until the bearings are at
    least `min_bearing_angle` apart and the triangle's smallest angle is at least `min_angle`."""

    box: float = 5.0
    half_fov: float = np.deg2rad(60.0)
    min_depth: float = 1.0
    max_depth: float = 10.0
    min_bearing_angle: float = np.deg2rad(2.0)
    min_angle: float = np.deg2rad(5.0)


def random_rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n,3,3) uniformly random rotations."""
    return Rotation.random(n, random_state=rng).as_matrix()


def random_p3p_instances(
    n: int, seed: int = 0, config: InstanceConfig = InstanceConfig()
) -> P3PInstances:
    """n random well-conditioned P3P instances (all points in front of the camera)."""
    rng = np.random.default_rng(seed)
    out = []
    have = 0
    while have < n:
        m = int((n - have) * 1.3) + 16
        cz = rng.uniform(np.cos(config.half_fov), 1.0, size=(m, 3))  # uniform on the spherical cap
        az = rng.uniform(0.0, 2.0 * np.pi, size=(m, 3))
        sz = np.sqrt(1.0 - cz * cz)
        f = np.stack([sz * np.cos(az), sz * np.sin(az), cz], axis=-1)
        depth = rng.uniform(config.min_depth, config.max_depth, size=(m, 3))
        R = random_rotations(m, rng)
        t = rng.uniform(-config.box, config.box, size=(m, 3))
        X = np.einsum("nij,npj->npi", R, depth[..., None] * f) + t[:, None, :]
        keep = np.ones(m, bool)
        for i, j in ((0, 1), (0, 2), (1, 2)):
            keep &= (
                np.arccos(np.clip(np.einsum("ni,ni->n", f[:, i], f[:, j]), -1, 1))
                > config.min_bearing_angle
            )
        for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
            u = X[:, j] - X[:, i]
            v = X[:, k] - X[:, i]
            cosang = np.einsum("ni,ni->n", u, v) / (
                np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1)
            )
            keep &= np.arccos(np.clip(cosang, -1, 1)) > config.min_angle
        out.append((f[keep], X[keep], R[keep], t[keep], depth[keep]))
        have += int(keep.sum())
    f, X, R, t, d = (np.concatenate(parts)[:n] for parts in zip(*out))
    return P3PInstances(bearings=f, points=X, R_wc=R, t_wc=t, depths=d)


def recovered(
    R_cand: np.ndarray,
    t_cand: np.ndarray,
    valid: np.ndarray,
    R_true: np.ndarray,
    t_true: np.ndarray,
    tol: float = RECOVERY_TOL,
) -> np.ndarray:
    """(N,) True where some valid candidate (R_cand (N,K,3,3), t_cand (N,K,3)) matches the truth."""
    rot_err = np.linalg.norm(R_cand - R_true[:, None], axis=(2, 3))
    trans_err = np.linalg.norm(t_cand - t_true[:, None], axis=2)
    return (valid & (rot_err < tol) & (trans_err < tol)).any(axis=1)


def opencv_p3p_loop(bearings: np.ndarray, points: np.ndarray, flag: int):
    """Per-instance Python loop over cv2.solveP3P with an identity camera; bearings become
    normalized image points f/f_z (points must be in front of the camera). Returns R_wc, t_wc,
    valid like solve_p3p."""
    n = bearings.shape[0]
    R_out = np.zeros((n, MAX_CANDIDATES, 3, 3))
    t_out = np.zeros((n, MAX_CANDIDATES, 3))
    valid = np.zeros((n, MAX_CANDIDATES), bool)
    image = np.ascontiguousarray(bearings[..., :2] / bearings[..., 2:3])
    K = np.eye(3)
    for i in range(n):
        count, rvecs, tvecs = cv2.solveP3P(points[i], image[i], K, None, flags=flag)
        for k in range(min(count, MAX_CANDIDATES)):
            R_cw, _ = cv2.Rodrigues(rvecs[k])
            R_out[i, k] = R_cw.T
            t_out[i, k] = -R_cw.T @ tvecs[k][:, 0]
            valid[i, k] = True
    return R_out, t_out, valid


def poselib_p3p_loop(bearings: np.ndarray, points: np.ndarray):
    """Per-instance Python loop over poselib.p3p(x: bearings (3,3), X: points (3,3)) -> list of
    CameraPose (world-to-camera R, t). Returns R_wc, t_wc, valid like solve_p3p."""
    import poselib  # the optional `test` extra: only this loop needs it

    n = bearings.shape[0]
    R_out = np.zeros((n, MAX_CANDIDATES, 3, 3))
    t_out = np.zeros((n, MAX_CANDIDATES, 3))
    valid = np.zeros((n, MAX_CANDIDATES), bool)
    for i in range(n):
        poses = poselib.p3p(bearings[i], points[i])
        for k, pose in enumerate(poses[:MAX_CANDIDATES]):
            R_cw = pose.R
            R_out[i, k] = R_cw.T
            t_out[i, k] = -R_cw.T @ pose.t
            valid[i, k] = True
    return R_out, t_out, valid


@dataclass(frozen=True)
class BenchRow:
    solver: str
    batched: bool
    seconds: float
    instances_per_s: float
    candidates_per_s: float
    mean_candidates: float
    recovery_rate: float


def run_p3p_benchmark(
    out_dir: str | Path, n: int = 100_000, seed: int = 0, rounds: int = 10, progress: bool = True
) -> dict:
    """Time every solver on the same n instances; write p3p_bench.json, p3p_bench.md and
    p3p_bench.png to out_dir; return the JSON dict.

    The machine is shared, so the instances are split into `rounds` slices and every solver
    runs on slice r before any runs on slice r+1 (interleaved): a load spike hits all solvers
    alike. Each solver's time is the sum over the slices; each gets one untimed warm-up."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    inst = random_p3p_instances(n, seed)

    def batched(method, polish):
        def solve(f, X):
            c = solve_p3p_by_name(f, X, method=method, polish=polish)
            return c.R_wc, c.t_wc, c.valid

        return solve

    solvers = [(f"graphloc.{m}", True, batched(m, False)) for m in METHODS]
    solvers.append(("graphloc.lambdatwist+polish", True, batched("lambdatwist", True)))
    solvers += [
        (name, False, lambda f, X, flag=flag: opencv_p3p_loop(f, X, flag))
        for name, flag in (
            ("cv2.solveP3P[P3P] loop", cv2.SOLVEPNP_P3P),
            ("cv2.solveP3P[AP3P] loop", cv2.SOLVEPNP_AP3P),
        )
    ]
    solvers.append(("poselib.p3p loop", False, poselib_p3p_loop))
    warm = min(n, 2000)
    for _, _, solve in solvers:
        solve(inst.bearings[:warm], inst.points[:warm])
    seconds = {name: 0.0 for name, _, _ in solvers}
    outputs = {name: [] for name, _, _ in solvers}
    edges = np.linspace(0, n, rounds + 1).astype(int)
    bar = tqdm(
        total=rounds * len(solvers), desc="P3P benchmark (solver x round)", disable=not progress
    )
    with bar:
        for lo, hi in zip(edges[:-1], edges[1:]):
            for name, _, solve in solvers:
                start = time.perf_counter()
                out = solve(inst.bearings[lo:hi], inst.points[lo:hi])
                seconds[name] += time.perf_counter() - start
                outputs[name].append(out)
                bar.update(1)
    rows: list[BenchRow] = []
    for name, is_batched, _ in solvers:
        R, t, valid = (np.concatenate(parts) for parts in zip(*outputs[name]))
        ok = recovered(R, t, valid, inst.R_wc, inst.t_wc)
        ncand = int(valid.sum())
        sec = seconds[name]
        rows.append(
            BenchRow(name, is_batched, sec, n / sec, ncand / sec, ncand / n, float(ok.mean()))
        )

    by_name = {r.solver: r for r in rows}
    default = by_name["graphloc.lambdatwist"]
    cv_p3p, pl = by_name["cv2.solveP3P[P3P] loop"], by_name["poselib.p3p loop"]
    ratios = {
        "default_vs_cv2_p3p_loop": default.instances_per_s / cv_p3p.instances_per_s,
        "default_vs_poselib_loop": default.instances_per_s / pl.instances_per_s,
    }
    targets = {
        "speed_vs_cv2_p3p_loop_ge_10x": ratios["default_vs_cv2_p3p_loop"] >= 10.0,
        "speed_vs_poselib_loop_ge_3x": ratios["default_vs_poselib_loop"] >= 3.0,
        "recovery_not_lower_than_peers": default.recovery_rate
        >= max(r.recovery_rate for r in rows if not r.batched),
    }
    result = {
        "n_instances": n,
        "seed": seed,
        "rounds": rounds,
        "recovery_tol": RECOVERY_TOL,
        "instance_config": {k: float(v) for k, v in asdict(InstanceConfig()).items()},
        "rows": [asdict(r) for r in rows],
        "ratios": ratios,
        "targets_met": targets,
    }
    (out_dir / "p3p_bench.json").write_text(dumps_json(result, indent=2))
    (out_dir / "p3p_bench.md").write_text(markdown_table(result))
    plot_benchmark(result, out_dir / "p3p_bench.png")
    return result


def markdown_table(result: dict) -> str:
    lines = [
        f"P3P benchmark: {result['n_instances']} instances (seed {result['seed']}), "
        f"recovery = some candidate within {result['recovery_tol']:g} of the truth (R and t)",
        "",
        "| solver | batched | instances/s | candidates/s | mean candidates | recovery rate |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for r in result["rows"]:
        lines.append(
            f"| {r['solver']} | {'yes' if r['batched'] else 'no (Python loop)'} | "
            f"{r['instances_per_s']:,.0f} | {r['candidates_per_s']:,.0f} | "
            f"{r['mean_candidates']:.3f} | {100 * r['recovery_rate']:.3f}% |"
        )
    lines += [
        "",
        *(f"- {k}: {v:.2f}x" for k, v in result["ratios"].items()),
        *(f"- target {k}: {'met' if v else 'NOT met'}" for k, v in result["targets_met"].items()),
        "",
    ]
    return "\n".join(lines)


def plot_benchmark(result: dict, path: Path) -> None:
    rows = result["rows"]
    names = [r["solver"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    colors = ["tab:blue" if r["batched"] else "tab:gray" for r in rows]
    speeds = [r["instances_per_s"] for r in rows]
    ax1.barh(names, speeds, color=colors)
    ax1.set_xscale("log")
    ax1.set_xlim(min(speeds) / 5, max(speeds) * 3)
    for y, v in enumerate(speeds):
        ax1.text(v * 1.05, y, f"{v:,.0f}", va="center", fontsize=8)
    ax1.set_xlabel("instances / s (log)")
    ax1.invert_yaxis()
    ax2.barh(names, [100 * (1 - r["recovery_rate"]) for r in rows], color=colors)
    ax2.set_xlabel(f"% instances not recovered (tol {result['recovery_tol']:g})")
    ax2.set_yticklabels([])
    ax2.invert_yaxis()
    fig.suptitle(
        f"P3P on {result['n_instances']} instances (blue: batched numpy, gray: per-instance loop)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    """`scripts/bench_p3p.py --out DIR [--n N] [--seed S] [--no-progress]`: run the benchmark,
    print its markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, type=Path, help="output directory")
    parser.add_argument("--n", type=int, default=100_000, help="number of random instances")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the instances")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)
    if not 1 <= args.n <= 10_000_000:
        parser.error(f"--n must be in [1, 10000000], got {args.n}")
    if not 0 <= args.seed <= 2**32 - 1:
        parser.error(f"--seed must be in [0, 2**32 - 1], got {args.seed}")
    result = run_p3p_benchmark(args.out, n=args.n, seed=args.seed, progress=not args.no_progress)
    print(markdown_table(result))
    return 0
