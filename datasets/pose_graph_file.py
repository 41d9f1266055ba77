"""Pose-graph files with discrete alternatives (issue 51): City10000's `EDGE2` lines and g2o 2D /
3D with Vertigo's switchable / max-mixture / mixture edges (docs/pose_graph_files.md), errors
naming file, line and field or counted skips."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from graphloc.textio import Sink, SkipReport, check_file, shown, text_lines

MAX_CANDIDATES = 64
MAX_KEY = 2**40
# tag -> (dimension, number of pose numbers, number of information entries)
_G2O_EDGES = {"EDGE_SE2": (2, 3, 6), "EDGE_SE3:QUAT": (3, 7, 21)}
# Vertigo's robust edge types (module docstring): tag -> (dimension, kind)
_G2O_MARKED = {
    "EDGE_SE2_SWITCHABLE": (2, "null"), "EDGE_SE3_SWITCHABLE": (3, "null"),
    "EDGE_SE2_MAXMIX": (2, "null"), "EDGE_SE3_MAXMIX": (3, "null"),
    "EDGE_SE2_MIXTURE": (2, "mixture"), "EDGE_SE3_MIXTURE": (3, "mixture"),
}  # fmt: skip
_G2O_COMPONENTS = {2: ("EDGE_SE2",), 3: ("EDGE_SE3:QUAT", "EDGE_SE3")}
_G2O_SWITCHES = ("VERTEX_SWITCH", "EDGE_SWITCH_PRIOR")
_G2O_VERTICES = {"VERTEX_SE2": (2, 3), "VERTEX_SE3:QUAT": (3, 7)}
TAGS = ("EDGE2", *_G2O_EDGES, *_G2O_VERTICES, *_G2O_MARKED, *_G2O_SWITCHES)  # the tags read


@dataclass(frozen=True)
class Measurement:
    """One edge: `candidates` are relative poses source -> target (Pose2 as x, y, theta; Pose3
    as x, y, z, qx, qy, qz, qw), `information` one matrix per candidate in GTSAM's tangent order
    (None: the file's default sigmas), `null` whether "no measurement" is an alternative too."""

    line: int
    source: int
    target: int
    candidates: tuple
    information: tuple | None = None
    null: bool = False

    @property
    def ambiguous(self) -> bool:
        return len(self.candidates) > 1 or self.null


@dataclass
class PoseGraphFile:
    path: Path
    dim: int  # 2 or 3
    format: str  # "city10000" or "g2o"
    measurements: list[Measurement]
    vertices: dict = field(default_factory=dict)  # id -> pose numbers, when the file has them
    skips: SkipReport = field(default_factory=SkipReport)


class _Line:
    """The fields of one line, each parsed with its position in the message."""

    def __init__(self, path: Path, line_no: int, parts: list[str]):
        self.where, self.parts = f"{path}: line {line_no}", parts

    def error(self, reason: str, index: int, name: str, problem: str):
        value = shown(self.parts[index]) if index < len(self.parts) else "missing"
        return reason, f"{self.where}: field {index + 1} ({name}) = {value}: {problem}"

    def integer(self, index: int, name: str, low: int = 0, high: int = MAX_KEY) -> int:
        if index >= len(self.parts):
            raise _Bad(*self.error("field_count", index, name, "missing"))
        try:
            value = int(self.parts[index])
        except ValueError:
            raise _Bad(*self.error("parse", index, name, "not an integer")) from None
        if not low <= value <= high:
            raise _Bad(*self.error("range", index, name, f"outside [{low}, {high}]"))
        return value

    def numbers(self, start: int, names: list[str]) -> np.ndarray:
        out = np.empty(len(names))
        for k, name in enumerate(names):
            i = start + k
            if i >= len(self.parts):
                raise _Bad(*self.error("field_count", i, name, "missing"))
            try:
                out[k] = float(self.parts[i])
            except ValueError:
                raise _Bad(*self.error("parse", i, name, "not a number")) from None
            if not math.isfinite(out[k]):
                raise _Bad(*self.error("non_finite", i, name, "not finite"))
        return out

    def exact_count(self, n: int, what: str) -> None:
        if len(self.parts) != n:
            message = f"{self.where}: {what}: expected {n} fields, got {len(self.parts)}"
            raise _Bad("field_count", message)


class _Bad(Exception):
    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason, self.message = reason, message


def read_pose_graph(
    path, on_error: str = "raise", null_on_loops: bool = False, max_edges: int | None = None
) -> PoseGraphFile:
    """The measurements (and vertices) of a City10000 or g2o file, in file order; `max_edges`
    stops after that many edges (City10000's "steps")."""
    path = Path(path)
    check_file(path, what="pose-graph file")
    sink = Sink(on_error, SkipReport())
    dims, formats, vertices, measurements = set(), set(), {}, []
    for line_no, text in text_lines(path):
        parts = text.split()
        if not parts or parts[0].startswith("#"):
            continue
        tag = parts[0]
        row = _Line(path, line_no, parts)
        try:
            if tag == "EDGE2":
                formats.add("city10000")
                dims.add(2)
                m = _city_edge(row, line_no)
            elif tag in _G2O_EDGES:
                formats.add("g2o")
                dims.add(_G2O_EDGES[tag][0])
                m = _g2o_edge(row, line_no, _G2O_EDGES[tag][0])
            elif tag in _G2O_MARKED:
                formats.add("g2o")
                dim, kind = _G2O_MARKED[tag]
                dims.add(dim)
                m = (
                    _g2o_mixture(row, line_no, dim)
                    if kind == "mixture"
                    else _g2o_edge(row, line_no, dim, null=True)
                )
            elif tag in _G2O_SWITCHES:
                sink.report.add(
                    "switch_variable",
                    f"{path}: line {line_no}: {tag}: Vertigo's switch variable, replaced by the "
                    "null component of its switchable edge",
                )
                continue
            elif tag in _G2O_VERTICES:
                dim, n = _G2O_VERTICES[tag]
                dims.add(dim)
                row.exact_count(2 + n, tag)
                vertices[row.integer(1, "id")] = row.numbers(2, [f"v{k}" for k in range(n)])
                continue
            else:
                sink.bad("unknown_tag", f"{path}: line {line_no}: tag {shown(tag)} not read")
                continue
        except _Bad as bad:
            sink.bad(bad.reason, bad.message)
            continue
        if len(dims) > 1:
            raise ValueError(f"{path}: line {line_no}: {tag} mixes 2D and 3D in one graph")
        if m.source == m.target:
            sink.bad("self_edge", f"{path}: line {line_no}: field 2 (source) = target {m.target}")
            continue
        if max_edges is not None and len(measurements) >= max_edges:
            break
        measurements.append(m)
    if not measurements:
        raise ValueError(f"{path}: no edge read ({sink.report.total} lines skipped)")
    if null_on_loops:
        measurements = [
            replace(m, null=True) if abs(m.target - m.source) != 1 else m for m in measurements
        ]
    return PoseGraphFile(
        path, dims.pop(), formats.pop() if len(formats) == 1 else "mixed", measurements,
        vertices, sink.report,
    )  # fmt: skip


def _city_edge(row: _Line, line_no: int) -> Measurement:
    source = row.integer(1, "source")
    row.integer(2, "robot")
    target = row.integer(3, "target")
    flag = row.integer(4, "ambiguous-loop flag", 0, 1)
    n = row.integer(5, "candidate count", 1, MAX_CANDIDATES)
    row.exact_count(6 + 3 * n, f"EDGE2 with {n} candidates")
    names = [f"{a}{k}" for k in range(n) for a in ("x", "y", "theta")]
    values = row.numbers(6, names).reshape(n, 3)
    return Measurement(line_no, source, target, tuple(values), None, bool(flag))


def _g2o_payload(row: _Line, dim: int, start: int) -> tuple[np.ndarray, np.ndarray]:
    """The relative pose and information matrix (GTSAM's tangent order) of a g2o edge whose
    pose numbers start at field `start`."""
    _, n_pose, n_info = _G2O_EDGES["EDGE_SE2" if dim == 2 else "EDGE_SE3:QUAT"]
    pose = row.numbers(
        start, ["x", "y", "theta"] if dim == 2 else list("xyz") + ["qx", "qy", "qz", "qw"]
    )
    upper = row.numbers(start + n_pose, [f"info{k}" for k in range(n_info)])
    size = 3 if dim == 2 else 6
    info = np.zeros((size, size))
    info[np.triu_indices(size)] = upper
    info = info + np.triu(info, 1).T
    if dim == 3:
        norm = float(np.linalg.norm(pose[3:]))
        if not 0.5 < norm < 2.0:
            raise _Bad(*row.error("quaternion", start + 3, "qx..qw", f"norm {norm:.3g} is not ~1"))
        pose[3:] /= norm
        order = [3, 4, 5, 0, 1, 2]  # g2o (t, R) -> GTSAM (R, t)
        info = info[np.ix_(order, order)]
    if np.any(np.linalg.eigvalsh(info) <= 0):
        raise _Bad(
            *row.error("information", start + n_pose, "information", "not positive definite")
        )
    return pose, info


def _payload_width(dim: int) -> int:
    _, n_pose, n_info = _G2O_EDGES["EDGE_SE2" if dim == 2 else "EDGE_SE3:QUAT"]
    return n_pose + n_info


def _g2o_edge(row: _Line, line_no: int, dim: int, null: bool = False) -> Measurement:
    """`EDGE_SE2` / `EDGE_SE3:QUAT i j pose info`: one certain measurement; `null`: Vertigo's
    `EDGE_SE*_SWITCHABLE i j switch_id pose info` / `EDGE_SE*_MAXMIX i j weight pose info`, one
    candidate and a null component (the switch id / weight is read, not used)."""
    start = 4 if null else 3
    row.exact_count(start + _payload_width(dim), row.parts[0])
    source, target = row.integer(1, "source"), row.integer(2, "target")
    if null:
        row.numbers(3, ["switch id" if row.parts[0].endswith("SWITCHABLE") else "weight"])
    pose, info = _g2o_payload(row, dim, start)
    return Measurement(line_no, source, target, (pose,), (info,), null)


def _g2o_mixture(row: _Line, line_no: int, dim: int) -> Measurement:
    """`EDGE_SE*_MIXTURE i j n` + n components `<edge tag> weight i j pose info`: n candidates
    of one measurement (the weights are read, not used: the candidates are equally likely)."""
    source, target = row.integer(1, "source"), row.integer(2, "target")
    n = row.integer(3, "component count", 1, MAX_CANDIDATES)
    width = 4 + _payload_width(dim)
    row.exact_count(4 + n * width, f"{row.parts[0]} with {n} components")
    poses, infos = [], []
    for k in range(n):
        base = 4 + k * width
        if row.parts[base] not in _G2O_COMPONENTS[dim]:
            raise _Bad(*row.error("parse", base, f"component {k + 1} tag", "not a g2o edge tag"))
        row.numbers(base + 1, [f"component {k + 1} weight"])
        for offset, name, value in ((2, "source", source), (3, "target", target)):
            if row.integer(base + offset, f"component {k + 1} {name}") != value:
                raise _Bad(*row.error("range", base + offset, f"component {k + 1} {name}",
                                      f"not the mixture's {name} {value}"))  # fmt: skip
        pose, info = _g2o_payload(row, dim, base + 4)
        poses.append(pose)
        infos.append(info)
    return Measurement(line_no, source, target, tuple(poses), tuple(infos))


def permute_candidates(measurements: list[Measurement], seed: int):
    """Each ambiguous measurement's candidates in a seeded random order (numpy's PCG64 via
    `default_rng(seed)`, one permutation per measurement in file order) -> (measurements, truth),
    `truth[i]` the new index of measurement i's first-listed candidate (City10000 lists the
    correct one first), for the measurements with more than one candidate."""
    rng = np.random.default_rng(seed)
    out, truth = [], {}
    for i, m in enumerate(measurements):
        if len(m.candidates) < 2:
            out.append(m)
            continue
        order = rng.permutation(len(m.candidates))
        info = None if m.information is None else tuple(m.information[k] for k in order)
        out.append(replace(m, candidates=tuple(m.candidates[k] for k in order), information=info))
        truth[i] = int(np.flatnonzero(order == 0)[0])
    return out, truth


def group_steps(measurements: list[Measurement]) -> list[list[tuple[int, Measurement]]]:
    """The measurements as online steps: [(index, m)] per newest pose, edges sorted (stably) by
    the larger of their two ids, so each step introduces at most one pose (an odometry chain)."""
    order = sorted(
        range(len(measurements)), key=lambda i: max(measurements[i].source, measurements[i].target)
    )
    steps, last = [], None
    for i in order:
        m = measurements[i]
        node = max(m.source, m.target)
        if node != last:
            steps.append([])
            last = node
        steps[-1].append((i, m))
    return steps
