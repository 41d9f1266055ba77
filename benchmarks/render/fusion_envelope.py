"""docs/results_fusion_envelope.md: the real map-fusion benchmark under other view noise and
densities (benchmarks.fusion_envelope, issue 16) from its JSON. Template:
templates/fusion_envelope.md.j2."""

from __future__ import annotations

import pandas as pd

from benchmarks.fusion_bench_real import PROTOCOL_KEEP, PROTOCOL_NOISE_M


def _cell(c: dict) -> str:
    """graphloc's successes / trials [false accepts] {not fused}, NEES, then FPFH's
    successes (an escaped bar: one markdown cell)."""
    fa = f"**[{c['false_accepts']}]**" if c["false_accepts"] else "[0]"
    nf = f" {{{c['not_fused']}}}" if c["not_fused"] else ""
    nees = (
        f", NEES {c['nees_mean']:.1f} {'in band' if c['nees_in_band'] else 'out of band'}"
        if c["nees_mean"] is not None
        else ""
    )
    return f"{c['successes']}/{c['trials']} {fa}{nf}{nees} \\| FPFH {c['fpfh_successes']}"


def context(report: dict) -> dict:
    entries = report["entries"]
    names = list(entries[0]["cells"]) if entries else []
    protocol = (PROTOCOL_NOISE_M, PROTOCOL_KEEP)
    rows = [
        [
            e["fragment"],
            f"{1000 * e['noise_m']:g}",
            f"{e['keep']:g}" + (" (protocol)" if (e["noise_m"], e["keep"]) == protocol else ""),
        ]
        + [_cell(e["cells"][name]) for name in names]
        for e in entries
    ]
    cells = [c for e in entries for c in e["cells"].values()]
    return {
        "report": report,
        "conditions": pd.DataFrame(rows, columns=["fragment", "noise [mm]", "kept", *names]),
        "false_accepts": sum(c["false_accepts"] for c in cells),
        "registrations": sum(c["trials"] for c in cells),
    }
