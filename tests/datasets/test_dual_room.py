"""The `dual-robot-room` scenario: geometry, sensors, ground truth, files, bad input."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from graphloc.datasets import scenario_class
from graphloc.datasets.dual_room import DualRoomConfig, DualRoomScenario, variant_config
from graphloc.datasets.room_scene import (
    LED_SIDE,
    T_CEILING_CAMERA,
    VARIANTS,
    CameraConfig,
    LidarConfig,
    led_positions,
    make_room,
)

SMALL_LIDAR = LidarConfig(beams=24, azimuths=180)


def small(variant="furnished", seed=0, **kw) -> DualRoomConfig:
    lidar = kw.pop("lidar", SMALL_LIDAR)
    return variant_config(variant, seed, frames=kw.pop("frames", 3), lidar=lidar, **kw)


@pytest.fixture(scope="module")
def scenario() -> DualRoomScenario:
    return DualRoomScenario.simulate(small())


def _scene(room):
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(room.mesh()))
    return scene


def test_registered_in_dataset_registry():
    assert scenario_class("dual-robot-room") is DualRoomScenario


def test_led_triangle_is_equilateral_with_seed_side():
    p = led_positions()
    d = np.linalg.norm(p[[0, 1, 2]] - p[[1, 2, 0]], axis=1)
    np.testing.assert_allclose(d, LED_SIDE, atol=1e-12)


def test_scans_lie_on_the_room_surfaces_at_ground_truth(scenario):
    scene = _scene(scenario.room)
    noise = scenario.config.lidar.range_noise
    for robot in ("ground", "ceiling"):
        for pose, pts in zip(scenario.poses[robot], scenario.scans[robot]):
            world = pts @ pose[:3, :3].T + pose[:3, 3]
            dist = scene.compute_distance(o3d.core.Tensor(world.astype(np.float32))).numpy()
            assert np.median(dist) < 1.5 * noise
            # spurious returns are the only points far from every surface
            far = (dist > 6 * noise).mean()
            assert far < 3 * scenario.config.lidar.spurious + 0.01


def test_noise_dropout_and_spurious_counts_match_the_config(scenario):
    c, cfg = scenario.counts["ground"], scenario.config.lidar
    hits = c["rays"] - c["no_return"]
    assert abs(c["dropout"] / hits - cfg.dropout) < 0.02
    assert 0 < c["spurious"] / hits < 3 * cfg.spurious
    assert sum(len(s) for s in scenario.scans["ground"]) == hits - c["dropout"]


def test_ceiling_robot_is_upside_down_and_ground_robot_level(scenario):
    Rg, Rc = scenario.poses["ground"][:, :3, :3], scenario.poses["ceiling"][:, :3, :3]
    np.testing.assert_allclose(Rg[:, :, 2], np.tile([0, 0, 1.0], (len(Rg), 1)), atol=1e-12)
    np.testing.assert_allclose(Rc[:, :, 2], np.tile([0, 0, -1.0], (len(Rc), 1)), atol=1e-12)
    assert np.all(scenario.poses["ceiling"][:, 2, 3] > scenario.room.size[2] - 0.2)


def test_both_robots_move(scenario):
    for robot in ("ground", "ceiling"):
        steps = np.linalg.norm(np.diff(scenario.poses[robot][:, :3, 3], axis=0), axis=1)
        assert np.all(steps > 0.01)


def test_led_pixels_are_noisy_projections_of_the_true_leds():
    cfg = small(camera=CameraConfig(pixel_noise=0.0))
    s = DualRoomScenario.simulate(cfg)
    cam = cfg.camera.pinhole()
    for f in range(len(s.times)):
        T_cam_ground = (
            np.linalg.inv(s.poses["ceiling"][f] @ T_CEILING_CAMERA) @ s.poses["ground"][f]
        )
        uv, vis = cam.project(led_positions() @ T_cam_ground[:3, :3].T + T_cam_ground[:3, 3])
        seen = s.led_visible[f]
        np.testing.assert_allclose(s.led_pixels[f][seen], uv[seen], atol=1e-9)
        assert np.isnan(s.led_pixels[f][~seen]).all()
    assert (
        s.led_visible.all(axis=1).sum() >= 2
    )  # placements are redrawn until the LEDs are seen twice


def test_furniture_tops_are_seen_only_from_the_ceiling():
    s = DualRoomScenario.simulate(
        small("furnished", seed=2, lidar=LidarConfig(beams=32, azimuths=240), frames=2)
    )
    top = 0.75  # first table of the furnished room: x 1.0..2.4, y 0.6..1.4, top at 0.75 m

    def on_top(robot):
        n = 0
        for pose, pts in zip(s.poses[robot], s.scans[robot]):
            w = pts @ pose[:3, :3].T + pose[:3, 3]
            n += int(
                (
                    (np.abs(w[:, 2] - top) < 0.01)
                    & (w[:, 0] > 1.1)
                    & (w[:, 0] < 2.3)
                    & (w[:, 1] > 0.7)
                    & (w[:, 1] < 1.3)
                ).sum()
            )
        return n

    assert on_top("ground") <= 2  # at most a spurious return
    assert on_top("ceiling") > 20


def test_rectangular_variant_is_symmetric_under_half_turn():
    room = make_room("rectangular")
    assert room.furniture == ()
    mesh = np.asarray(room.mesh().vertices)
    centre = np.array(room.size) / 2
    turned = (mesh - centre) * [-1, -1, 1] + centre
    assert {tuple(v) for v in np.round(mesh, 9)} == {tuple(v) for v in np.round(turned, 9)}


def test_variants_differ_and_low_overlap_has_short_range():
    rooms = {v: make_room(v) for v in VARIANTS}
    assert len(rooms["furnished"].furniture) > len(rooms["empty"].furniture) > 0
    assert (
        variant_config("low_overlap", 0).lidar.max_range
        < variant_config("furnished", 0).lidar.max_range
    )


def test_same_seed_same_data_other_seed_other_placement():
    a, b = DualRoomScenario.simulate(small(seed=5)), DualRoomScenario.simulate(small(seed=5))
    np.testing.assert_array_equal(a.scans["ground"][0], b.scans["ground"][0])
    c = DualRoomScenario.simulate(small(seed=6))
    assert not np.allclose(a.poses["ground"][0], c.poses["ground"][0])


def test_write_load_round_trip(scenario, tmp_path):
    scenario.write(tmp_path)
    assert (tmp_path / "scans" / "ground" / "000000.ply").is_file()
    back = DualRoomScenario.load(tmp_path)
    for robot in ("ground", "ceiling"):
        np.testing.assert_allclose(back.poses[robot], scenario.poses[robot], atol=1e-9)
        for x, y in zip(back.scans[robot], scenario.scans[robot]):
            np.testing.assert_allclose(x, y, atol=1e-5)
    np.testing.assert_allclose(back.led_pixels, scenario.led_pixels, atol=1e-3)
    np.testing.assert_allclose(back.T_ground0_ceiling0, scenario.T_ground0_ceiling0, atol=1e-9)
    assert back.config == scenario.config


def test_load_rejects_bad_files(scenario, tmp_path):
    scenario.write(tmp_path)
    csv_path = tmp_path / "led_pixels.csv"
    lines = csv_path.read_text().splitlines()
    csv_path.write_text("\n".join(lines[:2] + ["0,0.0,1,nan,3.0"] + lines[2:]) + "\n")
    with pytest.raises(ValueError, match=r"led_pixels.csv:3"):
        DualRoomScenario.load(tmp_path)
    csv_path.write_text("\n".join(lines) + "\n")
    tum = tmp_path / "poses_ground.tum"
    rows = tum.read_text().splitlines()
    rows[1], rows[2] = rows[2], rows[1]  # time goes backwards
    tum.write_text("\n".join(rows) + "\n")
    with pytest.raises(ValueError, match="poses_ground.tum.*backwards"):
        DualRoomScenario.load(tmp_path)
    with pytest.raises(FileNotFoundError, match="meta.json"):
        DualRoomScenario.load(tmp_path / "nothing")


def test_config_validation():
    with pytest.raises(ValueError, match="variant"):
        DualRoomConfig(variant="castle")
    with pytest.raises(ValueError, match="frames"):
        DualRoomConfig(frames=1)
    with pytest.raises(ValueError, match="offset"):
        DualRoomConfig(min_offset=2.0, max_offset=1.0)


def test_a_guessed_ceiling_robot_is_still_registered_from_its_hypotheses(tmp_path):
    """The ground -> ceiling transform through the team graph (batch) on the furnished room's
    seed 1, within the benchmark's target (scripts/bench_team_dual_room.py): the ceiling
    camera's pixel stream of the moving ground robot is never decided, its first set's guess
    places the ceiling robot, and the scan section must still register it from the tracker's
    hypotheses (f75b4ed skipped them there: 45.8 deg / 204 cm, no scan-match factor)."""
    from dataclasses import replace

    from benchmarks.team_dual_room import TARGET, _errors, _relative
    from graphloc.datasets import open_run
    from graphloc.pipelines.team_graph import GraphConfig, default_lag, solve
    from graphloc.runner.team_run import team_graph

    scenario = DualRoomScenario.simulate(variant_config("furnished", 1))
    scenario.write(tmp_path)
    run = open_run(tmp_path)
    graph = team_graph(run, GraphConfig())
    assert graph.counts.get("factors_scan_match", 0) > 0
    config = replace(graph.config, lag=default_lag(run, graph.config))
    result = solve(replace(graph, config=config), mode="batch")
    g, c = run.index("ground"), run.index("ceiling")
    rot_deg, trans_cm = _errors(
        _relative(result.estimate[g], result.estimate[c]), scenario.T_ground0_ceiling0
    )
    assert rot_deg < TARGET[0] and trans_cm < TARGET[1], (rot_deg, trans_cm)
