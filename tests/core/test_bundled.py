"""Bundled files from a checkout: the sample, templates and static folders; `facesvg convert --sample`."""

from __future__ import annotations

import json

from conftest import ROOT, SAMPLE
from converter import bundled
from converter.cli import main


def test_a_checkout_finds_its_top_level_folders():
    assert bundled.sample_path() == SAMPLE
    assert bundled.asset_dir("webapp", "templates") == ROOT / "templates"
    assert (bundled.asset_dir("webapp", "static") / "style.css").is_file()


def test_convert_sample_writes_to_the_working_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["convert", "--sample", "--size", "64", "--end", "3", "-q", "--report", "r.json"]) == 0
    assert (tmp_path / "face.svg").read_bytes().startswith(b"<svg")
    assert json.loads((tmp_path / "r.json").read_text())["counts"]["frames"] == 3
    assert main(["convert", str(SAMPLE), "--sample", "-o", "x.svg"]) == 2
    assert "not both" in capsys.readouterr().err
    assert main(["convert", "-o", "x.svg"]) == 2
    assert "--sample" in capsys.readouterr().err and not (tmp_path / "x.svg").exists()
