"""Build the real indoor scan fragments of tests/data/real_room for map fusion.

tum_fr3_office.ply, from a depth image:

Input: one TUM RGB-D depth image (Sturm et al., IROS 2012, CC BY 4.0; the Freiburg 3 office
desk frame that Open3D ships as TestData/RGBD/other_formats/TUM_depth.png). Steps, all Open3D
built-ins: back-projection with the Freiburg 3 intrinsics (fx 535.4, fy 539.2, cx 320.1, cy
247.6, depth scale 5000, depth cut at --max-depth), voxel downsampling, RANSAC plane fit of the
floor (the plane whose normal is closest to the camera's -y axis among the --planes largest),
then a rotation making the floor normal +z (gravity up) with the optical axis in the x-z plane;
the origin stays at the sensor (the floor is at z = -camera height); then a seeded random
subsample to at most --points points, stored as float32 PLY.

    .venv/bin/python scripts/make_real_fragment.py TUM_depth.png --out tests/data/real_room

redwood_livingroom.ply, from a point cloud (PCD / PLY, e.g. the Redwood living-room fragment
that Open3D ships as fragment.pcd): RANSAC planes, the floor the largest one, its normal turned
toward the side holding the other points (the room stands on its floor); rotation making it +z
with the old x axis (y if the floor faces x) kept in the x-z plane; the origin moved to the
middle of the points' x-y extent, --height metres above the floor (a ground robot's sensor);
every point kept unless there are more than --points (seeded subsample); float32 PLY. With
--camera-frame (a cloud in a camera's frame, y down and z forward, as RGB-D fragments such as
3DMatch's are stored) the floor is the plane most aligned with the camera's -y instead, as for a
depth image: in a fragment seen from a room's middle a wall can be the largest plane.

    .venv/bin/python scripts/make_real_fragment.py fragment.pcd --height 1.0 \
        --name redwood_livingroom.ply
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import open3d as o3d

from graphloc.mapping.io import read_points

FR3 = (640, 480, 535.4, 539.2, 320.1, 247.6)  # width, height, fx, fy, cx, cy (TUM Freiburg 3)


def ransac_planes(pcd: o3d.geometry.PointCloud, planes: int, seed: int) -> list:
    """Up to `planes` RANSAC planes (2 cm), each found among the points the earlier ones left:
    [(unit normal n, offset d of n.p + d = 0, inlier count)]."""
    o3d.utility.random.seed(seed)
    rest, out = pcd, []
    for _ in range(planes):
        if len(rest.points) < 3:
            break
        (a, b, c, d), inliers = rest.segment_plane(0.02, 3, 2000)
        out.append((np.array([a, b, c]), float(d), len(inliers)))
        rest = rest.select_by_index(inliers, invert=True)
    return out


def rotation_to_z(n: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Rotation whose rows are the new axes: z = n, x = `axis` made orthogonal to n."""
    x = axis - (axis @ n) * n
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(n, x), n])


def floor_alignment(
    pcd: o3d.geometry.PointCloud, planes: int, seed: int
) -> tuple[np.ndarray, float]:
    """(3x3 rotation camera -> gravity frame with the floor normal as +z, camera height [m]):
    the floor is the plane most aligned with the camera's up (-y in the camera frame)."""
    up = [(-n, -d) if n[1] > 0 else (n, d) for n, d, _ in ransac_planes(pcd, planes, seed)]
    n, d = max(up, key=lambda nd: -nd[0][1])
    if -n[1] < 0.8:
        raise ValueError("no floor plane within 37 deg of the camera's vertical")
    # the camera's optical axis (z) as the new +x direction
    return rotation_to_z(n, np.array([0.0, 0.0, 1.0])), d  # d: camera height above the floor


def cloud_floor_alignment(
    pcd: o3d.geometry.PointCloud, planes: int, seed: int
) -> tuple[np.ndarray, float]:
    """(3x3 rotation to a frame with the floor normal as +z, the floor's z in that frame): the
    floor is the largest of `planes` RANSAC planes, its normal toward the other points."""
    n, d, _ = max(ransac_planes(pcd, planes, seed), key=lambda p: p[2])
    if np.median(np.asarray(pcd.points) @ n + d) < 0:  # the room on the + side of its floor
        n, d = -n, -d
    axis = np.eye(3)[0] if abs(n[0]) < 0.9 else np.eye(3)[1]  # an old axis not along n
    return rotation_to_z(n, axis), -d  # the floor n.p + d = 0 lies at z = -d


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("depth", help="TUM depth PNG (uint16, 5000 per metre), or a PCD / PLY cloud")
    p.add_argument("--out", default="tests/data/real_room")
    p.add_argument("--name", default="tum_fr3_office.ply", help="output file name")
    p.add_argument("--height", type=float, default=1.0, help="cloud input: sensor height [m]")
    p.add_argument("--max-depth", type=float, default=6.0)
    p.add_argument("--voxel", type=float, default=0.02)
    p.add_argument("--points", type=int, default=30_000)
    p.add_argument("--planes", type=int, default=3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--camera-frame",
        action="store_true",
        help="cloud input: in a camera's frame (y down); the floor is the plane most aligned "
        "with -y, not the largest",
    )
    args = p.parse_args(argv)
    if Path(args.depth).suffix.lower() in (".pcd", ".ply"):
        return from_cloud(args)
    depth = o3d.io.read_image(args.depth)
    if np.asarray(depth).dtype != np.uint16:
        raise ValueError(f"{args.depth}: expected a uint16 depth PNG")
    intr = o3d.camera.PinholeCameraIntrinsic(*FR3)
    pcd = o3d.geometry.PointCloud.create_from_depth_image(
        depth, intr, depth_scale=5000.0, depth_trunc=args.max_depth
    )
    n_raw = len(pcd.points)
    pcd = pcd.voxel_down_sample(args.voxel)
    R, height = floor_alignment(pcd, args.planes, args.seed)
    pts = np.asarray(pcd.points) @ R.T
    rng = np.random.default_rng(args.seed)
    if len(pts) > args.points:
        pts = pts[np.sort(rng.choice(len(pts), args.points, replace=False))]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts.astype(np.float32)))
    path = out / args.name
    o3d.t.io.write_point_cloud(str(path), cloud)
    ext = pts.max(0) - pts.min(0)
    print(
        f"{n_raw} depth points -> {len(pts)} in {path}; extent {np.round(ext, 2)} m, "
        f"camera height {height:.2f} m"
    )
    return 0


def from_cloud(args) -> int:
    """The point-cloud input (module docstring)."""
    points = read_points(args.depth)  # checked against its header, in metres
    if len(points) < 100:
        raise ValueError(f"{args.depth}: {len(points)} points, need at least 100")
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if args.camera_frame:
        R, height = floor_alignment(pcd, args.planes, args.seed)
        floor_z = -height
    else:
        R, floor_z = cloud_floor_alignment(pcd, args.planes, args.seed)
    pts = np.asarray(pcd.points) @ R.T
    lo, hi = pts.min(0), pts.max(0)
    pts -= np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, floor_z + args.height])
    rng = np.random.default_rng(args.seed)
    n_in = len(pts)
    if len(pts) > args.points:
        pts = pts[np.sort(rng.choice(len(pts), args.points, replace=False))]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / args.name
    cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts.astype(np.float32)))
    o3d.t.io.write_point_cloud(str(path), cloud)
    print(
        f"{n_in} points -> {len(pts)} in {path}; extent {np.round(pts.max(0) - pts.min(0), 2)} m,"
        f" floor at z = {-args.height:.2f} m"
    )
    return 0


if __name__ == "__main__":
    try:
        raise SystemExit(main())
    except (OSError, ValueError) as exc:  # a missing or unreadable input: one line, code 2
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
