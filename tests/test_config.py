"""graphloc.config: declarative field checks name Class.field and the value; options derive
from a config dataclass's fields (type, default, help) and build the config back."""

import argparse
import math
from dataclasses import dataclass, field

import pytest

from graphloc.cli import main
from graphloc.config import (
    add_config_arguments,
    check,
    config_from_args,
    option_fields,
    parse_overrides,
)
from graphloc.geometry.p3p import P3PConfig
from graphloc.hypotheses import TrackerConfig


@dataclass(frozen=True)
class Demo:
    sigma: float = field(default=1.0, metadata={"help": "noise [m]"})
    count: int = 3
    low: float = 0.2
    high: float = 0.8
    mode: str = "a"
    enabled: bool = True
    limit: float | None = None
    pair: tuple = (1.0, 2.0)

    def __post_init__(self):
        check(
            self,
            positive=("sigma",),
            nonnegative=("limit",),
            integer={"count": 1},
            interval={"low": (0.0, "high", "[)"), "high": (0.0, 1.0, "(]")},
            choices={"mode": ("a", "b")},
            optional=("limit",),
        )


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"sigma": 0.0}, "Demo.sigma must be finite and > 0, got 0.0"),
        ({"sigma": math.inf}, "Demo.sigma must be finite and > 0, got inf"),
        ({"sigma": "1"}, "Demo.sigma must be finite and > 0, got '1'"),
        ({"sigma": math.nan}, "Demo.sigma must be finite and > 0, got nan"),
        ({"count": 0}, "Demo.count must be an integer >= 1, got 0"),
        ({"count": 2.0}, "Demo.count must be an integer >= 1, got 2.0"),
        ({"count": True}, "Demo.count must be an integer >= 1, got True"),
        ({"low": 0.9}, r"Demo.low must be in \[0, high = 0.8\), got 0.9"),
        ({"high": 1.5}, r"Demo.high must be in \(0, 1\], got 1.5"),
        ({"mode": "c"}, r"Demo.mode must be one of \('a', 'b'\), got 'c'"),
        ({"limit": -1.0}, "Demo.limit must be finite and >= 0, got -1.0"),
    ],
)
def test_check_names_class_field_rule_and_value(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Demo(**kwargs)


def test_check_accepts_valid_values_and_optional_none():
    Demo(limit=None, low=0.0, high=1.0, count=1, mode="b")
    Demo(limit=0.0)


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
    with pytest.raises(ValueError, match="Demo.count: expected an integer"):
        parse_overrides(Demo, {"count": "1.5"})
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
    }
    parser = argparse.ArgumentParser(exit_on_error=False)
    parser.add_argument("--config")
    add_config_arguments(parser, Demo, exclude=("high",))
    text = parser.format_help()
    assert "--sigma FLOAT" in text and "noise [m] (default 1.0)" in text
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
