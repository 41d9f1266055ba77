import numpy as np
import pytest

from graphloc.candidates import CandidateSet
from graphloc.keys import (
    decode,
    decode_many,
    landmark_key,
    marker_key,
    mode_key,
    pose_key,
    sensor_key,
)


def test_pose_keys_are_unique_and_decode():
    keys = {pose_key(r, t) for r in range(5) for t in range(100)}
    assert len(keys) == 500
    assert decode(pose_key(3, 12)) == ("x", 3, 12)
    assert decode(landmark_key(7)) == ("l", 7, 0)
    assert decode(mode_key(9)) == ("m", 9, 0)
    assert len({pose_key(0, 0), landmark_key(0), mode_key(0)}) == 3


@pytest.mark.parametrize("robot,t", [(-1, 0), (0, -1), (1000, 0), (0, 10**9)])
def test_pose_key_rejects_out_of_range(robot, t):
    with pytest.raises(ValueError):
        pose_key(robot, t)


def test_marker_keys_are_unique_and_decode():
    keys = {marker_key(r, m) for r in (0, 1, 999) for m in (0, 2, 999)}
    assert len(keys) == 9 and not keys & {pose_key(r, m) for r in (0, 1) for m in (0, 2)}
    assert decode(marker_key(7, 3)) == ("k", 7, 3)
    with pytest.raises(ValueError):
        marker_key(0, 1000)


def test_sensor_keys_are_unique_and_decode_to_their_body_pose():
    keys = {sensor_key(r, s, t) for r in (0, 1, 999) for s in (0, 1, 999) for t in (0, 10**9 - 1)}
    assert len(keys) == 18 and not keys & {pose_key(r, t) for r in (0, 1) for t in (0, 1)}
    assert decode(sensor_key(7, 3, 12)) == ("s", 7, 12)
    assert decode(sensor_key(999, 999, 10**9 - 1)) == ("s", 999, 10**9 - 1)
    with pytest.raises(ValueError):
        sensor_key(0, 1000, 0)
    with pytest.raises(ValueError):
        sensor_key(1000, 0, 0)


def test_candidate_set_validates_and_normalizes():
    R = np.stack([np.eye(3)] * 2)
    c = CandidateSet(R=R, t=np.zeros((2, 3)), scores=np.array([1.0, 3.0]))
    assert np.allclose(c.weights(), [0.25, 0.75])
    assert len(c.poses()) == 2
    with pytest.raises(ValueError, match="t must be"):
        CandidateSet(R=R, t=np.zeros((3, 3)), scores=np.ones(2))
    with pytest.raises(ValueError, match="NaN"):
        CandidateSet(R=R, t=np.full((2, 3), np.nan), scores=np.ones(2))


def test_decode_many_is_decode_of_each():
    keys = [
        pose_key(3, 12),
        landmark_key(100_000_005),
        mode_key(7),
        marker_key(2, 9),
        pose_key(0, 0),
        sensor_key(5, 2, 33),
        sensor_key(999, 999, 10**9 - 1),
    ]
    kind, first, second = decode_many(keys)
    assert [(str(a), int(b), int(c)) for a, b, c in zip(kind, first, second)] == [
        decode(k) for k in keys
    ]
