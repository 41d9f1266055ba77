"""`SectionFactors`: what one section of the team graph (`live.events.EventGraph`'s candidate
streams) returns -- its factors, the skips it counted and the marker points it made -- instead of
writing into lists it is handed."""

from __future__ import annotations

from dataclasses import dataclass, field

from graphloc.io import SkipReport


@dataclass
class SectionFactors:
    """What a section of the graph makes: factors (time of the newest pose, factor, type), the
    skips it counted, a static target's new marker points (key -> world position: their
    initial values) and a moving target's per-set points ((key, target, node, body-frame
    position) each: their initial values come from the target's pose)."""

    factors: list = field(default_factory=list)
    skips: SkipReport = field(default_factory=SkipReport)
    marker_points: dict = field(default_factory=dict)
    frame_points: list = field(default_factory=list)

    def merge(self, other: "SectionFactors") -> None:
        """`other`'s factors, skips and points after these."""
        self.factors += other.factors
        self.skips.merge(other.skips)
        self.marker_points.update(other.marker_points)
        self.frame_points += other.frame_points
