"""The one place GTSAM keys are built, in the style of gtsam.symbol_shorthand:

robot r's pose at step t             Symbol('x', r * STRIDE + t)
landmark l                           Symbol('l', l)
mode of observation k                Symbol('m', k)
marker j of static robot r           Symbol('k', r * MAX_MARKERS + j)
marker j of candidate set n's target Symbol('q', n * MAX_MARKERS + j)
sensor slot s of robot r at step t   Symbol('s', (s * MAX_ROBOTS + r) * STRIDE + t)"""

from __future__ import annotations

import gtsam
import numpy as np

STRIDE = 1_000_000_000
MAX_ROBOTS = 1_000
_INDEX_MASK = (1 << 56) - 1  # gtsam.Symbol: the character in the top byte, the index below


def pose_key(robot: int, t: int) -> int:
    """Key of robot `robot`'s pose at time index `t` (both non-negative ints)."""
    if not (0 <= int(robot) < MAX_ROBOTS):
        raise ValueError(f"robot index {robot} outside [0, {MAX_ROBOTS})")
    if not (0 <= int(t) < STRIDE):
        raise ValueError(f"time index {t} outside [0, {STRIDE})")
    return gtsam.symbol("x", int(robot) * STRIDE + int(t))


def landmark_key(landmark: int) -> int:
    """Key of landmark `landmark` (non-negative int)."""
    if int(landmark) < 0:
        raise ValueError(f"landmark id {landmark} is negative")
    return gtsam.symbol("l", int(landmark))


def mode_key(observation: int) -> int:
    """Key of the discrete variable choosing among the candidates of observation `observation`."""
    if int(observation) < 0:
        raise ValueError(f"observation index {observation} is negative")
    return gtsam.symbol("m", int(observation))


MAX_MARKERS = 1_000


def marker_key(robot: int, marker: int) -> int:
    """Key of marker `marker` of robot `robot`'s layout as a world point."""
    if not (0 <= int(robot) < MAX_ROBOTS):
        raise ValueError(f"robot index {robot} outside [0, {MAX_ROBOTS})")
    if not (0 <= int(marker) < MAX_MARKERS):
        raise ValueError(f"marker index {marker} outside [0, {MAX_MARKERS})")
    return gtsam.symbol("k", int(robot) * MAX_MARKERS + int(marker))


def frame_marker_key(observation: int, marker: int) -> int:
    """Key of marker `marker` of the target of candidate set `observation` as a world point at
    that set's time (a moving target's markers: one point per set and marker)."""
    if int(observation) < 0:
        raise ValueError(f"observation index {observation} is negative")
    if not (0 <= int(marker) < MAX_MARKERS):
        raise ValueError(f"marker index {marker} outside [0, {MAX_MARKERS})")
    return gtsam.symbol("q", int(observation) * MAX_MARKERS + int(marker))


MAX_SENSORS = 1_000


def sensor_key(robot: int, slot: int, t: int) -> int:
    """Key of the pose of robot `robot`'s offset sensor `slot` (one per distinct extrinsics of
    the robot) at time index `t`."""
    if not (0 <= int(slot) < MAX_SENSORS):
        raise ValueError(f"sensor slot {slot} outside [0, {MAX_SENSORS})")
    body = pose_key(robot, t) & _INDEX_MASK  # checks robot and t
    return gtsam.symbol("s", int(slot) * MAX_ROBOTS * STRIDE + body)


def decode(key: int) -> tuple[str, int, int]:
    """Inverse of the builders: ('x', robot, t), ('l', id, 0), ('m', obs, 0),
    ('k', robot, marker), ('q', observation, marker) or ('s', robot, t) (a sensor pose: its
    robot and time index, as its body pose's; the slot is left out)."""
    kind, index = chr(key >> 56), key & _INDEX_MASK  # gtsam.Symbol's layout, no GTSAM call
    if kind == "x":
        return kind, index // STRIDE, index % STRIDE
    if kind == "s":
        return kind, (index // STRIDE) % MAX_ROBOTS, index % STRIDE
    if kind in ("k", "q"):
        return kind, index // MAX_MARKERS, index % MAX_MARKERS
    return kind, index, 0


def decode_many(keys) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`decode` of many keys at once: (kind characters (N,) str, first (N,) int, second (N,)
    int), as `decode` gives them (one vectorized pass over gtsam.Symbol's layout: the
    character in the top byte, the index below)."""
    k = np.asarray(keys, dtype=np.uint64).reshape(-1)
    index = (k & np.uint64(_INDEX_MASK)).astype(np.int64)
    kind = (k >> np.uint64(56)).astype(np.uint8).view("S1").astype(str)
    pose = np.isin(kind, ("x", "s"))
    stride = np.where(pose, STRIDE, np.where(np.isin(kind, ("k", "q")), MAX_MARKERS, 0))
    first = np.where(stride > 0, index // np.maximum(stride, 1), index)
    first = np.where(kind == "s", first % MAX_ROBOTS, first)
    second = np.where(stride > 0, index % np.maximum(stride, 1), 0)
    return kind, first, second


def key_name(key: int) -> str:
    """GTSAM's name of a key (x0, l3, ...), or the number when GTSAM cannot format it (a
    symbol character that is not text raises UnicodeDecodeError in DefaultKeyFormatter)."""
    try:
        return gtsam.DefaultKeyFormatter(key)
    except UnicodeDecodeError:
        return str(key)
