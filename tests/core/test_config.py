"""graphloc.config: config dataclasses checked by pydantic name Class.field, the rule and the
value; options derive from a config dataclass's fields (type, default, description) and build
the config back."""

import argparse
import dataclasses
import inspect
import math
import subprocess
import sys
from typing import Literal

import pytest

from graphloc.cli import main
from graphloc.config import add_config_arguments, config_from_args, option_fields, parse_overrides
from graphloc.config_schema import ConfigError, config_dataclass, setting
from graphloc.geometry.p3p import P3PConfig
from graphloc.hypotheses import TrackerConfig


@config_dataclass
class Inner:
    scale: float = setting(1.0, gt=0.0)


@config_dataclass
class Demo:
    sigma: float = setting(1.0, gt=0.0, description="noise [m]")
    count: int = setting(3, ge=1)
    low: float = setting(0.2, ge=0.0)
    high: float = setting(0.8, gt=0.0, le=1.0)
    mode: Literal["a", "b"] = "a"
    enabled: bool = True
    limit: float | None = setting(None, ge=0.0)
    dof: float = setting(6.0, gt=0.0, allow_inf_nan=True)
    pair: tuple[float, float] = (1.0, 2.0)
    inner: Inner = dataclasses.field(default_factory=Inner)

    def __post_init__(self):
        if not self.low < self.high:
            raise ValueError(f"Demo.low must be in [0, high = {self.high:g}), got {self.low}")


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"sigma": 0.0}, "Demo.sigma must be finite and > 0, got 0.0"),
        ({"sigma": math.inf}, "Demo.sigma must be finite and > 0, got inf"),
        ({"sigma": "1"}, "Demo.sigma: expected float, got '1'"),
        ({"sigma": math.nan}, "Demo.sigma must be finite and > 0, got nan"),
        ({"count": 0}, "Demo.count must be an integer >= 1, got 0"),
        ({"count": 2.0}, "Demo.count: expected int, got 2.0"),
        ({"count": True}, "Demo.count: expected int, got True"),
        ({"sigma": True}, "Demo.sigma: expected float, got True"),
        ({"low": 0.9}, r"Demo.low must be in \[0, high = 0.8\), got 0.9"),
        ({"high": 1.5}, r"Demo.high must be in \(0, 1\], got 1.5"),
        ({"mode": "c"}, r"Demo.mode must be one of \('a', 'b'\), got 'c'"),
        ({"limit": -1.0}, "Demo.limit must be finite and >= 0, got -1.0"),
        ({"dof": -1.0}, r"Demo.dof must be in \(0, inf\], got -1.0"),
        ({"dof": math.nan}, r"Demo.dof must be in \(0, inf\], got nan"),
        ({"enabled": 1}, "Demo.enabled: expected bool, got 1"),
        ({"mode": 1}, r"Demo.mode must be one of \('a', 'b'\), got 1"),
        ({"pair": [1.0, 2.0]}, r"Demo.pair: Input should be a valid tuple, got \[1.0, 2.0\]"),
        ({"pair": (1.0, "x")}, r"Demo.pair: expected float values, got 'x'"),
        ({"pair": (1.0,)}, r"Demo.pair: expected a list of 2 values, got \(1.0,\)"),
        ({"inner": {"scale": 2.0}}, "Demo.inner: Input should be an instance of Inner"),
        ({"bogus": 1}, "Demo: unknown field 'bogus'; known: sigma, count"),
    ],
)
def test_a_rule_names_class_field_rule_and_value(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        Demo(**kwargs)


def test_valid_values_optional_none_and_allowed_inf_are_taken():
    Demo(limit=None, low=0.0, high=1.0, count=1, mode="b", sigma=2)  # an int for a float
    assert Demo(limit=0.0, dof=math.inf).dof == math.inf
    assert Demo(2.0, 4).count == 4  # positional, as any dataclass
    assert list(inspect.signature(Demo).parameters)[:2] == ["sigma", "count"]
    assert Demo(inner=Inner(scale=3.0)).inner.scale == 3.0


def test_replace_checks_again_and_the_class_stays_a_frozen_dataclass():
    demo = Demo()
    assert dataclasses.replace(demo, count=5) == Demo(count=5)
    with pytest.raises(ConfigError, match="Demo.count must be an integer >= 1, got 0"):
        dataclasses.replace(demo, count=0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        demo.count = 2
    assert hash(demo) == hash(Demo()) and dataclasses.asdict(demo)["inner"] == {"scale": 1.0}


def test_a_nested_rule_names_the_path_of_the_field():
    with pytest.raises(ConfigError, match="Demo.inner: Inner.scale must be finite and > 0") as exc:
        parse_overrides(Demo, {"inner": {"scale": "0"}})
    assert exc.value.key == "inner.scale"


def test_defining_and_reading_a_config_class_loads_no_pydantic():
    """pydantic loads on the first construction, not where a class is defined or its options
    are read (`graphloc VERB --help`, issue 47)."""
    code = """
import argparse, sys
from graphloc.config import add_config_arguments
from graphloc.pipelines.team_graph.options import RunOptions
add_config_arguments(argparse.ArgumentParser(), RunOptions)
assert "pydantic" not in sys.modules
RunOptions(keyframe_dt=0.5)
assert "pydantic" in sys.modules
"""
    subprocess.run([sys.executable, "-c", code], check=True)


def test_migrated_configs_use_it():
    with pytest.raises(ValueError, match=r"TrackerConfig.release_threshold must be in \(0, "):
        TrackerConfig(release_threshold=0.99)
    TrackerConfig(student_dof=math.inf)  # inf = Gaussian innovations
    with pytest.raises(ValueError, match="P3PConfig.polish_iters must be an integer >= 0"):
        P3PConfig(polish_iters=-2)
    P3PConfig(depth_refine_iters=None)


def test_parse_overrides_types_and_errors():
    assert parse_overrides(Demo, {"sigma": "2", "count": "4", "enabled": "false"}) == {
        "sigma": 2.0,
        "count": 4,
        "enabled": False,
    }
    assert parse_overrides(Demo, {"limit": "0.5", "mode": "b"}) == {"limit": 0.5, "mode": "b"}
    with pytest.raises(ValueError, match="unknown field 'bogus'"):
        parse_overrides(Demo, {"bogus": 1})
    with pytest.raises(ConfigError, match="Demo.count: expected int, got 1.5"):
        Demo(**parse_overrides(Demo, {"count": "1.5"}))
    with pytest.raises(ConfigError, match="Demo.sigma must be a finite number within"):
        parse_overrides(Demo, {"sigma": "1e308"})
    assert parse_overrides(Demo, {"pair": "[3, 4]"}) == {"pair": (3, 4)}
    with pytest.raises(ValueError, match="Demo.sigma: expected float, got .abc."):
        parse_overrides(Demo, {"sigma": "abc"})


def test_options_derive_from_the_fields(tmp_path):
    assert option_fields(Demo) == {
        "sigma": float,
        "count": int,
        "low": float,
        "high": float,
        "mode": str,
        "enabled": bool,
        "limit": float,
        "dof": float,
    }
    parser = argparse.ArgumentParser(exit_on_error=False)
    parser.add_argument("--config")
    add_config_arguments(parser, Demo, exclude=("high",))
    text = parser.format_help()
    assert "--sigma FLOAT" in text and "noise [m] (default 1.0)" in text
    assert "--mode STR" in text and "(a, b) (default 'a')" in text
    assert "--enabled, --no-enabled" in text and "--high" not in text and "--pair" not in text
    args = parser.parse_args(["--count", "5", "--no-enabled"])
    assert config_from_args(Demo, args) == Demo(count=5, enabled=False)
    toml = tmp_path / "demo.toml"
    toml.write_text('count = 7\nmode = "b"\n')
    args = parser.parse_args(["--config", str(toml), "--count", "6"])
    assert config_from_args(Demo, args) == Demo(count=6, mode="b")  # command line wins
    toml.write_text("bogus = 1\n")
    with pytest.raises(ValueError, match="demo.toml: line 1: Demo: unknown field 'bogus'"):
        config_from_args(Demo, parser.parse_args(["--config", str(toml)]))
    with pytest.raises(ValueError, match="Demo.count must be an integer >= 1, got 0"):
        config_from_args(Demo, parser.parse_args(["--count", "0"]))


def test_verbs_take_options_from_the_config_fields(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["simulate", "kaushik-p3p-error", "--out", str(run), "--frames", "3"]) == 0
    assert main(["validate", str(run), "--no-landmarks", "--keyframe-dt", "0.5"]) == 0
    assert '"graph"' in capsys.readouterr().out
    assert main(["validate", str(run), "--keyframe-dt", "0"]) == 2
    err = capsys.readouterr().err
    assert "RunOptions.keyframe_dt must be in [0.001, 3600], got 0" in err
