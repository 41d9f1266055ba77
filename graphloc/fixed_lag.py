"""The fixed-lag window of an online `Session` (SessionConfig.lag > 0): iSAM2 marginalizing, with
`marginalizeLeaves`, every variable added more than `lag` seconds before the newest, kept a leaf
by a constrained ordering by add time."""

from __future__ import annotations

import collections
import math
from typing import Iterable

import gtsam
import numpy as np

from graphloc.session_config import SessionConfig


class FixedLagWindow:
    """The bookkeeping of one fixed-lag iSAM2: the add stamp of each live variable, the ordering
    groups (one per live stamp), the most recent keys, and the marginalized variables' last
    estimates (`frozen`)."""

    def __init__(self, isam: gtsam.ISAM2, config: SessionConfig):
        self.isam = isam
        self.config = config
        self.touched: dict[int, float] = {}  # live key -> its stamp
        self.frozen = gtsam.Values()  # marginalized variables' last estimates
        self._frozen_keys: set[int] = set()  # their keys (a membership test without a GTSAM call)
        self._newest = -np.inf
        self._groups = gtsam.KeyGroupMap()  # live key -> the rank of its stamp
        self._ranks: dict[float, int] = {}  # live stamp -> its rank (ordering group)
        self._by_stamp: dict[float, list] = {}  # live stamp -> its keys, oldest stamp first
        # the most recent keys, always re-eliminated: more than the groups there can be
        stamps = 2 + math.ceil(config.lag / (config.marginalize_every or config.lag))
        self._in_newest = 0  # live keys with the newest stamp
        self._recent: collections.deque = collections.deque(maxlen=stamps + 2)

    @property
    def frozen_keys(self) -> frozenset | set:
        """The marginalized variables' keys (do not modify)."""
        return self._frozen_keys

    def estimate(self, keys: list | None = None) -> gtsam.Values:
        """Every variable (frozen and live), or only `keys` (one `calculateEstimate(keys)` of
        the live ones, one `extract` of the frozen ones); GTSAM failures raise RuntimeError."""
        if keys is None:
            out = gtsam.Values(self.frozen)
            out.insert(self.isam.calculateEstimate())
            return out
        frozen = [k for k in keys if k in self._frozen_keys]
        live = [k for k in keys if k not in self._frozen_keys] if frozen else keys
        out = self.isam.calculateEstimate(live) if live else gtsam.Values()
        if frozen:
            out.insert(self.frozen.extract(frozen))
        return out

    def update(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, t: float) -> None:
        """One fixed-lag update: new keys stamped with t rounded down to `marginalize_every`, iSAM2
        given a constrained ordering (one group per live stamp, oldest first) so that the keys older
        than `lag` are leaves, marginalized by `marginalizeLeaves` at their full back-substitution
        estimate (docs/design_core.md, "Fixed lag")."""
        quantum = self.config.marginalize_every or self.config.lag
        now = math.floor(t / quantum) * quantum  # add times never go back
        old = []
        if now > self._newest:  # a new stamp: the next rank; only it can make keys old
            self._newest = now
            self._ranks[now] = len(self._ranks)
            self._in_newest = 0
            self._by_stamp[now] = []
            limit = now - self.config.lag - 1e-9 * quantum
            while next(iter(self._by_stamp)) < limit:  # stamps in time order
                old += self._by_stamp.pop(next(iter(self._by_stamp)))
        rank = self._ranks[now]
        extra = _key_list(self._recent) if self._recent else None
        for k in values.keys():
            self.touched[k] = now
            self._by_stamp[now].append(k)
            self._groups.insert2(k, rank)
            self._recent.append(k)
        self._in_newest += values.size()
        # this update only: the keys of the new factors that have the newest stamp go last
        # (iSAM2's own default constrains the new factors' keys last), one group above the
        # newest stamp's (used only when that stamp has other keys)
        top = [k for k in set(graph.keyVector()) if self.touched[k] == now]
        bump = 0 < len(top) < self._in_newest
        for k in top if bump else ():
            self._groups.insert2(k, rank + 1)
        self.isam.update(graph, values, [], self._groups, None, extra)
        for k in top if bump else ():
            self._groups.insert2(k, rank)
        for _ in range(self.config.extra_updates):
            extra = _key_list(self._recent)
            empty = gtsam.NonlinearFactorGraph()
            self.isam.update(empty, gtsam.Values(), [], self._groups, None, extra)
        if not old:
            return
        # the marginalized keys keep their estimate -- of a full back-substitution: iSAM2's
        # own stops where the solution changes less than the wildfire threshold, which is
        # harmless for a live variable (a later update refines it) but would freeze a stale
        # one --; the live stamps are renumbered from 0
        self.frozen.insert(self.isam.calculateBestEstimate().extract(old))
        self.isam.marginalizeLeaves(_key_list(old))
        self._frozen_keys.update(old)
        for k in old:
            del self.touched[k]
        self._ranks = {stamp: r for r, stamp in enumerate(self._by_stamp)}
        self._groups = gtsam.KeyGroupMap()
        for stamp, keys in self._by_stamp.items():
            for k in keys:
                self._groups.insert2(k, self._ranks[stamp])
        self._recent = collections.deque(
            (k for k in self._recent if k in self.touched), maxlen=self._recent.maxlen
        )


def _key_list(keys: Iterable[int]) -> gtsam.KeyList:
    out = gtsam.KeyList()
    for k in keys:
        out.push_back(k)
    return out
