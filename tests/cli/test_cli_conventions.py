"""CLI conventions of every verb (issue 13): `--version`; `-v` / `-q` and `--no-progress`;
`--config FILE` with the schema of the verb's options (both from its config dataclass); the
output folder announced; a bad config file is one error naming file, line and field."""

from __future__ import annotations

import argparse
import json

import pytest

from graphloc.cli import VERBS, build_parser, main
from graphloc.config import config_from_args
from graphloc.pipelines.map_fusion.options import FuseMapsOptions


def _verb_parsers() -> dict:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_every_verb_has_the_common_options_and_a_config_file():
    parsers = _verb_parsers()
    assert set(parsers) == set(VERBS)
    for verb, p in parsers.items():
        flags = {s for a in p._actions for s in a.option_strings}
        assert {"-v", "-q", "--no-progress"} <= flags, verb
        if verb != "simulate":  # simulate: --config is an option of the scenario (NAME --help)
            assert "--config" in flags, verb


def test_version(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0 and capsys.readouterr().out.startswith("graphloc ")


def _fuse(tmp_path, text: bytes | str, capsys) -> str:
    cfg = tmp_path / "fusion.toml"
    cfg.write_bytes(text if isinstance(text, bytes) else text.encode())
    argv = ["fuse-maps", "--simulate", "dual-robot-room", "--config", str(cfg)]
    assert main(argv + ["--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


def test_fuse_maps_config_errors_name_file_line_and_field(tmp_path, capsys):
    err = _fuse(tmp_path, b"seed = 1\n[fusion]\npixel_sigma = 0.5 # \xff\n", capsys)
    assert "fusion.toml: line 3: not UTF-8" in err
    err = _fuse(tmp_path, "seed = 1\n[fusion.registration]\nvoxels = 0.04\n", capsys)
    assert "fusion.toml: line 3:" in err and "unknown field 'voxels'" in err
    err = _fuse(tmp_path, "frames = 3\n[fusion]\n\npixel_sigma = 'half'\n", capsys)
    assert "fusion.toml: line 4:" in err and "FusionConfig.pixel_sigma: expected float" in err
    err = _fuse(tmp_path, "[fusion]\nguess_sigma = [0.1]\n", capsys)
    assert "fusion.toml: line 2:" in err and "guess_sigma: expected a list of 2" in err
    err = _fuse(tmp_path, "[fusion.acceptance]\nmin_inlier_ratio = 0.6\nmin_overlap = -1\n", capsys)
    assert "fusion.toml: line 3:" in err and "AcceptanceConfig.min_overlap" in err
    err = _fuse(tmp_path, "seed = -2\n", capsys)
    assert "fusion.toml: line 1:" in err and "FuseMapsOptions.seed" in err
    err = _fuse(tmp_path, "[fusion.registration\nvoxel = 1\n", capsys)
    assert "fusion.toml: not valid TOML" in err and "line 1" in err
    err = _fuse(tmp_path, "bogus = 1\n", capsys)
    assert "fusion.toml: line 1: FuseMapsOptions: unknown field 'bogus'" in err


def test_fuse_maps_config_fills_the_nested_fusion_config(tmp_path):
    parser = argparse.ArgumentParser()
    parser.add_argument("--config")
    p = tmp_path / "fusion.toml"
    p.write_text(
        "seed = 3\nhint-sigma = '2 0.05'\nhint = '0 0 2 1 0 0 0'\n"
        "[fusion]\nguess_sigma = [0.1, 0.2]\nrobust = false\n"
        "[fusion.registration]\nvoxel = 0.04\nscales = [0.16, 0.04]\n"
        "max_correspondence = [0.5, 0.06]\nmax_iterations = [20, 20]\n"
        "[fusion.acceptance]\nmin_inlier_ratio = 0.7\n"
    )
    opts = config_from_args(FuseMapsOptions, parser.parse_args(["--config", str(p)]))
    reg = opts.fusion.registration
    assert opts.seed == 3 and opts.hint_sigma == "2 0.05" and not opts.fusion.robust
    assert reg.voxel == 0.04 and reg.scales == (0.16, 0.04) and reg.max_iterations == (20, 20)
    assert opts.fusion.acceptance.min_inlier_ratio == 0.7
    assert opts.fusion.guess_sigma == (0.1, 0.2)


def test_quiet_verbose_and_the_output_folder(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["simulate", "kaushik-p3p-error", "--out", str(run), "--frames", "3"]) == 0
    out, err = capsys.readouterr()
    assert "wrote kaushik-p3p-error" in out and f"outputs in {run}" in err
    quiet = tmp_path / "quiet"
    argv = ["simulate", "kaushik-p3p-error", "--out", str(quiet), "--frames", "3", "-q"]
    assert main(argv) == 0 and (quiet / "manifest.json").exists()
    assert capsys.readouterr() == ("", "")
    cfg = tmp_path / "smooth.toml"
    cfg.write_text("keyframe_dt = 0.25\n")
    est = tmp_path / "est"
    assert main(["smooth", str(run), "--out", str(est), "--config", str(cfg), "-v"]) == 0
    out, err = capsys.readouterr()
    metrics = json.loads((est / "metrics.json").read_text())
    assert metrics["options"]["keyframe_dt"] == 0.25
    assert "graphloc: smooth: options" in err and "exit 0 after" in err
    assert f"outputs in {est}" in err and out  # the summary on stdout
    with pytest.raises(SystemExit):  # -q and -v exclude each other (argparse: usage, exit 2)
        main(["smooth", str(run), "--out", str(est), "-q", "-v"])


def test_import_takes_its_config_file(tmp_path, capsys):
    cfg = tmp_path / "r.toml"
    cfg.write_text("topic = 'x.yaml'\n")
    argv = ["import", str(tmp_path / "none.bag"), "--config", str(cfg), "--out", str(tmp_path)]
    assert main(argv) == 2
    assert "r.toml: line 1: ImportOptions: unknown field 'topic'" in capsys.readouterr().err
