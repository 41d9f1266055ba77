"""The simulator protocol and `graphloc simulate`: every scenario class implements
`Scenario` and writes a valid log with ground truth; options derive from its config."""

import dataclasses
import inspect

import numpy as np
import pytest

from benchmarks.seed_baselines import genuine_p3p_errors
from graphloc.cli import main
from graphloc.config import parse_overrides
from graphloc.datasets import scenario_class, scenario_names
from graphloc.datasets.kaushik import SIDE, KaushikConfig, led_triangle, simulate
from graphloc.datasets.scenarios import generate
from graphloc.io import iter_records
from graphloc.manifest import read_manifest

SMALL = {
    "feng-deterministic": {},
    "feng-probabilistic": {"max_time": "1.0"},
    "kaushik-p3p-error": {"frames": "4"},
    "breitenmoser-target": {"frames": "3"},
}


@pytest.mark.parametrize("name", sorted(SMALL))
def test_generate_writes_readable_log_with_groundtruth(tmp_path, name):
    path = generate(name, tmp_path / name, seed=2, overrides=SMALL[name])
    manifest = read_manifest(path.parent)
    records = list(iter_records(path.parent))
    assert records, name
    # the climber's views: marker pixels, or (seed 000 Sec. VI-A) bearings of the ground robots
    views = [
        r
        for r in records
        if type(r).__name__ in ("MarkerPixel", "Bearing3D") and r.robot == "climber"
    ]
    values = [[m.u, m.v] if hasattr(m, "u") else [m.x, m.y, m.z] for m in views]
    assert views and np.isfinite(values).all()
    assert manifest.robot("climber").tables["groundtruth"].endswith(".tum")
    gt = np.loadtxt(path.parent / manifest.robot("climber").tables["groundtruth"])
    assert gt.shape[1] == 8 and np.allclose(np.linalg.norm(gt[:, 4:], axis=1), 1.0)
    assert len(np.unique([m.time for m in views])) == len(gt)


# the lead's simulators conform to the protocol in their own modules (issue 13); strict: once
# they do, the marker must go (and scenarios._NOT_YET_CONFORMING with it)
SCENARIOS = [
    "feng-deterministic",
    "feng-probabilistic",
    "kaushik-p3p-error",
    "breitenmoser-target",
    "dual-robot-room",
    "crawler-pair",
]


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_scenario_class_implements_the_protocol(name):
    cls = scenario_class(name)
    assert cls.name == name and dataclasses.is_dataclass(cls.config_class)
    assert isinstance(inspect.getattr_static(cls, "generate"), classmethod)
    params = list(inspect.signature(cls.generate).parameters.values())
    assert [p.name for p in params[:2]] == ["out_dir", "seed"]
    assert params[-1].kind is inspect.Parameter.VAR_KEYWORD


def test_loaders_are_not_scenarios():
    assert "mrclam" not in scenario_names()
    with pytest.raises(ValueError, match="unknown scenario 'mrclam'; scenarios: breitenmoser"):
        scenario_class("mrclam")


def test_simulate_verb_and_bad_input(tmp_path, capsys):
    assert (
        main(["simulate", "kaushik-p3p-error", "--out", str(tmp_path / "k"), "--frames", "3"]) == 0
    )
    assert (tmp_path / "k" / "manifest.json").is_file()
    assert main(["simulate", "no-such-scenario", "--out", str(tmp_path / "x")]) == 2
    assert main(["simulate", "mrclam", "--out", str(tmp_path / "x")]) == 2
    assert (
        main(["simulate", "kaushik-p3p-error", "--out", str(tmp_path / "x"), "--bogus", "1"]) == 2
    )
    assert (
        main(["simulate", "kaushik-p3p-error", "--out", str(tmp_path / "x"), "--focal-mm", "x"])
        == 2
    )
    assert main(["simulate", "kaushik-p3p-error", "--frames", "3"]) == 2
    err = capsys.readouterr().err
    assert "no-such-scenario" in err and "--bogus" in err and "KaushikConfig.focal_mm" in err
    assert "--out DIR is required" in err
    assert not (tmp_path / "x").exists()


def test_simulate_options_are_the_config_fields(capsys):
    with pytest.raises(SystemExit) as done:
        main(["simulate", "breitenmoser-target", "--help"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    for flag in ("--frames INT", "--d-min FLOAT", "--save-images, --no-save-images"):
        assert flag in out


def test_parse_overrides_types():
    assert parse_overrides(KaushikConfig, {"focal_mm": "26", "runs": "5"}) == {
        "focal_mm": 26.0,
        "runs": 5,
    }
    with pytest.raises(ValueError, match="noise_variance"):  # checked by the class's rules
        KaushikConfig(**parse_overrides(KaushikConfig, {"noise_variance": "[1]"}))
    with pytest.raises(ValueError, match="KaushikConfig.runs: expected int, got 1.5"):
        KaushikConfig(**parse_overrides(KaushikConfig, {"runs": "1.5"}))
    with pytest.raises(ValueError, match="KaushikConfig.focal_mm: expected float, got 'x'"):
        parse_overrides(KaushikConfig, {"focal_mm": "x"})


def test_kaushik_geometry_and_genuine_candidate():
    tri = led_triangle()
    sides = np.linalg.norm(tri - np.roll(tri, 1, axis=0), axis=1)
    assert np.allclose(sides, SIDE)
    noiseless = genuine_p3p_errors(simulate(KaushikConfig(runs=5, frames=3, noise_variance=0.0)))
    assert len(noiseless) == 15 and noiseless.max() < 1e-6
    noisy = genuine_p3p_errors(simulate(KaushikConfig(runs=5, frames=3, noise_variance=3.0)))
    assert noisy.mean() > noiseless.mean()
    with pytest.raises(ValueError, match="focal_mm"):
        KaushikConfig(focal_mm=float("nan"))
    with pytest.raises(ValueError, match="lose an LED"):
        simulate(KaushikConfig(runs=2, frames=2, height=0.5, focal_mm=36.0))


@pytest.mark.slow
def test_dual_robot_room_through_simulate(tmp_path):
    assert main(["simulate", "dual-robot-room", "--out", str(tmp_path / "d"), "--frames", "2"]) == 0
    assert any((tmp_path / "d").iterdir())


def test_feng_probabilistic_logs_the_covariance_of_its_odometry_model(tmp_path):
    sigmas = {}
    for model in ("per_axis", "isotropic"):
        path = generate(
            "feng-probabilistic",
            tmp_path / model,
            seed=1,
            overrides={"max_time": "1.0", "odometry_model": model},
        )
        rows = [r for r in iter_records(path.parent) if type(r).__name__ == "RelativePose3D"]
        sigmas[model] = np.array([[r.sigma_tx, r.sigma_ty, r.sigma_tz] for r in rows])
    # isotropic: 15 % of the step length on every axis; per axis: of each component
    iso = sigmas["isotropic"]
    assert np.allclose(iso, iso[:, :1]) and not np.allclose(sigmas["per_axis"], iso)
