"""Tables of a graphloc log that become observations in batches (docs/log_format.md):
`markers` rows grouped by image -> P3P candidate sets in one batched solve
(`graphloc.vision.marker_poses`, seed 000 Sec. III-B / seed 004 Sec. II-C: three distinct
markers, up to 4 candidates; seed 001 Sec. IV-C: four identical markers, 24 x 4 hypotheses gated
by the fourth marker), `candidates` rows -> candidate sets as logged, and a robot's `scans` ->
KISS-ICP odometry steps (`graphloc.mapping.odometry`). Called by
`graphloc.datasets.graphloc_log.read_team_run` with the rows it grouped.
"""

from __future__ import annotations

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graphloc.candidates import CandidateSet
from graphloc.datasets.camera_tables import camera_from_params, positive_param
from graphloc.io import MANIFEST, Sink
from graphloc.run import CandidateObservation, MarkerPixels, Motion, ScanObservation
from graphloc.vision.marker_poses import p3p_candidate_sets


def marker_observations(
    groups: dict, robots: tuple, manifest, d: dict, sink: Sink, used: dict
) -> list:
    """Marker pixels grouped by (time, observer, sensor, target) -> P3P candidate sets, all
    three-marker instances of the run in one batched solve."""
    out = []
    by_setup: dict = {}
    for (time, ri, sensor, ti), rows in groups.items():
        target = robots[ti]
        lines = sorted(r.line for r in rows)
        where = (
            f"{manifest.root / manifest.robots[ri].tables['markers']}: lines {lines[0]}-{lines[-1]}"
        )
        if target.markers is None:
            raise ValueError(
                f"{where}: field 'target': robot {target.name!r} has no 'markers' layout in the "
                f"manifest"
            )
        marks = np.array([r.marker for r in rows])
        if (marks < 0).any() or (marks >= len(target.markers)).any():
            sink.bad(
                "unknown_marker",
                f"{where}: field 'marker': {marks.tolist()} outside the layout of "
                f"{len(target.markers)} markers",
            )
            continue
        if len(np.unique(marks)) != len(marks) and not target.identical_markers:
            sink.bad(
                "duplicate_marker", f"{where}: field 'marker': a marker appears twice in one image"
            )
            continue
        if len(rows) < 3:
            sink.bad("too_few_markers", f"{where}: {len(rows)} markers seen, P3P needs 3")
            continue
        by_setup.setdefault((ri, sensor, ti), []).append(
            (time, marks, np.array([[r.u, r.v] for r in rows]), where)
        )
    for (ri, sensor, ti), frames in by_setup.items():
        T_bs, params = robots[ri].sensors[sensor]
        where = f"{manifest.root / MANIFEST}: robot {robots[ri].name!r} sensor {sensor!r}"
        camera = camera_from_params(params, where)
        sigma = positive_param(params, "pixel_sigma", d["pixel_sigma"], where)
        target = robots[ti]
        sets = p3p_candidate_sets(
            camera,
            [f[2] for f in frames],
            [f[1] for f in frames],
            target.markers,
            [f[0] for f in frames],
            sigma,
            identical=target.identical_markers,
            observer=robots[ri].name,
            observed=target.name,
        )
        for (time, marks, uv, lines), cs in zip(frames, sets):
            if cs is None or (len(cs) == 0 and not cs.meta.get("inconsistent")):
                sink.bad(
                    "no_p3p_solution", f"{lines}: fields 'u, v': no pose fits the marker pixels"
                )
                continue
            # an inconsistent set (no pose passes the pixel chi-square) stays, empty: the team
            # graph counts it in its stream and never decides it
            pixels = None if target.identical_markers else MarkerPixels(marks, uv, camera, sigma)
            out.append(CandidateObservation(time, ri, ti, gtsam.Pose3(T_bs), cs, pixels))
    return out


SCAN_SIGMAS = (0.002, 0.01)  # [rad, m] per KISS-ICP step where the scanner's params give none


def scan_odometry(groups: dict, robots: tuple, manifest, report) -> tuple[list, list]:
    """Each robot's scans (rows of its `scans` table, per scanner) -> KISS-ICP odometry
    (`graphloc.mapping.odometry`) -> one relative-pose step per consecutive pair of scans, in
    the body frame (through the scanner's extrinsics), covariance from the scanner's
    `icp_sigmas` [rot rad, trans m]; and the scans themselves (`ScanObservation`, by path) for
    the inter-robot registration of the team graph."""
    if not groups:
        return [], []
    # Open3D and KISS-ICP load only for runs that have scans
    from graphloc.mapping.io import check_scan_units, read_scan
    from graphloc.mapping.odometry import run_odometry

    out, observed, sequences = [], [], {}
    for (ri, sensor), rows in groups.items():
        T_bs, params = robots[ri].sensors[sensor]
        E = gtsam.Pose3(T_bs)
        observed += [ScanObservation(r.time, ri, E, manifest.root / r.path) for r in rows]
        scans = []
        for row in rows:
            table = manifest.root / manifest.robots[ri].tables["scans"]
            try:
                points, dropped = read_scan(manifest.root / row.path)
            except (OSError, ValueError) as exc:
                raise ValueError(f"{table}: line {row.line}: field 'path': {exc}") from None
            scans.append(points)
            if dropped:
                where = f"{table}: line {row.line}: field 'path'"
                report.add(
                    "scan_points_nonfinite", f"{where}: {dropped} non-finite points", dropped
                )
        sequences[(ri, sensor)] = (scans, [manifest.root / r.path for r in rows])
    if len({ri for ri, _ in groups}) > 1:  # registered with each other: one unit, checked first
        check_scan_units({f"{robots[ri].name}/{s}": seq for (ri, s), seq in sequences.items()})
    for (ri, sensor), rows in groups.items():
        T_bs, params = robots[ri].sensors[sensor]
        E = gtsam.Pose3(T_bs)
        sig = params.get("icp_sigmas", SCAN_SIGMAS)
        cov = np.diag([float(sig[0]) ** 2] * 3 + [float(sig[1]) ** 2] * 3)
        A = E.AdjointMap()
        steps = run_odometry(sequences[(ri, sensor)][0]).increments()
        for a, b, step in zip(rows[:-1], rows[1:], steps):
            rel = E.compose(gtsam.Pose3(step)).compose(E.inverse())
            out.append(Motion(ri, a.time, b.time, rel, A @ cov @ A.T))
    return out, observed


def candidate_observations(groups: dict, robots: tuple, d: dict, manifest) -> list:
    """`candidates` rows grouped by (time, observer, sensor, target) -> candidate sets as
    logged, each candidate with the sensor's `candidate_sigmas` (rot rad, trans m)."""
    out = []
    for (time, ri, sensor, ti), rows in groups.items():
        T_bs, params = robots[ri].sensors[sensor]
        sig = params.get("candidate_sigmas", d["candidate_sigmas"])
        rows = sorted(rows, key=lambda r: r.k)
        q = np.array([[r.qx, r.qy, r.qz, r.qw] for r in rows])
        R = Rotation.from_quat(q / np.linalg.norm(q, axis=1, keepdims=True)).as_matrix()
        t = np.array([[r.tx, r.ty, r.tz] for r in rows])
        cov = np.broadcast_to(
            np.diag([sig[0] ** 2] * 3 + [sig[1] ** 2] * 3), (len(rows), 6, 6)
        ).copy()
        cs = CandidateSet(
            R,
            t,
            np.array([r.score for r in rows]),
            time=time,
            observer=robots[ri].name,
            observed=robots[ti].name,
            source="candidates-table",
            covariance=cov,
        )
        out.append(CandidateObservation(time, ri, ti, gtsam.Pose3(T_bs), cs))
    return out
