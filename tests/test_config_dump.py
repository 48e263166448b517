"""``holoslam config --dump``: every setting of a run as YAML that loads back to the same configuration."""

from __future__ import annotations

import dataclasses

import yaml

from holoslam.cli import main
from holoslam.config import RunConfig, dump_run_config, load_run_config, to_mapping


def _leaves(d, prefix=""):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _leaves(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}"


def test_the_dump_holds_every_setting_and_loads_back(tmp_path):
    text = dump_run_config()
    assert sorted(_leaves(yaml.safe_load(text))) == sorted(_leaves(to_mapping(RunConfig())))
    path = tmp_path / "run.yaml"
    path.write_text(text)
    assert load_run_config(path) == RunConfig()
    assert "# m per cell" in text  # a setting's source comment (unit) beside it


def test_the_cli_dumps_the_defaults_or_a_merged_configuration(tmp_path, capsys):
    assert main(["config", "--dump"]) == 0
    assert yaml.safe_load(capsys.readouterr().out) == to_mapping(RunConfig())
    mine = tmp_path / "mine.yaml"
    mine.write_text("grid: {resolution: 0.1}\n")
    out = tmp_path / "full.yaml"
    assert main(["config", "--dump", "--config", str(mine), "-o", str(out)]) == 0
    want = dataclasses.replace(RunConfig(), grid=dataclasses.replace(RunConfig().grid, resolution=0.1))
    assert load_run_config(out) == want
    assert main(["config"]) == 2 and "--dump" in capsys.readouterr().err
