"""`LiveView`: the Foxglove live view of a running team (Foxglove SDK WebSocket server,
`graphloc[live]`): per robot its pose, path, tf and 1-sigma position ellipsoid (docs/live.md,
"--view")."""

from __future__ import annotations

from time import monotonic

import numpy as np

FRAME = "map"


def _timestamp(t: float):
    from foxglove.messages import Timestamp

    ns = int(round(t * 1e9))
    return Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def _parts(pose):
    """(position Vector3, orientation Quaternion) of a gtsam.Pose3 (Foxglove messages are
    built, not read back: each use takes new ones)."""
    from foxglove.messages import Quaternion, Vector3

    q, p = pose.rotation().toQuaternion(), pose.translation()
    return (
        Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
        Quaternion(x=q.x(), y=q.y(), z=q.z(), w=q.w()),
    )


def _pose(pose):
    from foxglove.messages import Pose

    position, orientation = _parts(pose)
    return Pose(position=position, orientation=orientation)


def position_ellipsoid(pose, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(1-sigma semi-axes (3,), rotation (3, 3) whose columns are the axes in `map`) of the
    position block of a Pose3 covariance in GTSAM's tangent order (body frame: R C_t R^T)."""
    R = pose.rotation().matrix()
    c = R @ np.asarray(cov, dtype=float)[3:, 3:] @ R.T
    w, v = np.linalg.eigh(0.5 * (c + c.T))
    if np.linalg.det(v) < 0:
        v[:, 0] = -v[:, 0]
    return np.sqrt(np.clip(w, 0.0, None)), v


class LiveView:
    """A Foxglove WebSocket server showing the team's latest poses (module docstring)."""

    def __init__(
        self, port: int = 8765, host: str = "127.0.0.1", context=None, path_period: float = 1.0
    ):
        import foxglove

        self.context = context if context is not None else foxglove.Context()
        self.server = foxglove.start_server(
            name="graphloc live", host=host, port=port, context=self.context
        )
        self.port = self.server.port
        self.path_period = path_period
        self._paths: dict = {}
        self._path_sent: dict = {}
        self._channels: dict = {}

    def _log(self, topic: str, msg, t: float) -> None:
        import foxglove.channels

        ch = self._channels.get(topic)
        if ch is None:  # the typed channel of the message's schema (PoseInFrameChannel, ...)
            make = getattr(foxglove.channels, f"{type(msg).__name__}Channel")
            ch = self._channels[topic] = make(topic, context=self.context)
        ch.log(msg, log_time=int(round(t * 1e9)))

    def show(self, poses: dict, time: float) -> None:
        """`poses`: robot -> (time, gtsam.Pose3, 6x6 covariance, GTSAM tangent order)."""
        from foxglove.messages import (
            Color,
            FrameTransform,
            FrameTransforms,
            Pose,
            PoseInFrame,
            PosesInFrame,
            Quaternion,
            SceneEntity,
            SceneUpdate,
            SpherePrimitive,
            TextPrimitive,
            Vector3,
        )
        from scipy.spatial.transform import Rotation

        stamp = _timestamp(time)
        entities, transforms = [], []
        for robot, (t, pose, cov) in poses.items():
            p = _pose(pose)
            self._log(
                f"/graphloc/{robot}/pose",
                PoseInFrame(timestamp=_timestamp(t), frame_id=FRAME, pose=p),
                time,
            )
            path = self._paths.setdefault(robot, [])
            path.append(pose)
            now = monotonic()
            if now - self._path_sent.get(robot, -np.inf) >= self.path_period:
                self._path_sent[robot] = now
                poses_so_far = [_pose(x) for x in path]
                self._log(
                    f"/graphloc/{robot}/path",
                    PosesInFrame(timestamp=stamp, frame_id=FRAME, poses=poses_so_far),
                    time,
                )
            transforms.append(
                FrameTransform(
                    timestamp=stamp,
                    parent_frame_id=FRAME,
                    child_frame_id=robot,
                    translation=_parts(pose)[0],
                    rotation=_parts(pose)[1],
                )
            )
            axes, rot = position_ellipsoid(pose, cov)
            qx, qy, qz, qw = Rotation.from_matrix(rot).as_quat()
            sig = np.sqrt(np.clip(np.diag(np.asarray(cov, dtype=float)), 0.0, None))
            label = (
                f"{robot}: pos sigma {100 * axes.max():.1f} cm, "
                f"rot sigma {np.degrees(sig[:3].max()):.2f} deg"
            )
            entities.append(
                SceneEntity(
                    timestamp=stamp,
                    frame_id=FRAME,
                    id=robot,
                    spheres=[
                        SpherePrimitive(
                            pose=Pose(
                                position=_parts(pose)[0],
                                orientation=Quaternion(x=qx, y=qy, z=qz, w=qw),
                            ),
                            size=Vector3(x=2 * axes[0], y=2 * axes[1], z=2 * axes[2]),
                            color=Color(r=0.2, g=0.5, b=1.0, a=0.4),
                        )
                    ],
                    texts=[
                        TextPrimitive(
                            pose=_pose(pose),
                            billboard=True,
                            font_size=14.0,
                            scale_invariant=True,
                            color=Color(r=1.0, g=1.0, b=1.0, a=1.0),
                            text=label,
                        )
                    ],
                )
            )
        if transforms:
            self._log("/tf", FrameTransforms(transforms=transforms), time)
            self._log("/graphloc/covariance", SceneUpdate(entities=entities), time)

    def close(self) -> None:
        self.server.stop()
