"""The suite stands alone: tests/data is intact and copies ../shared/data; missing full data skips (fails under CI)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

import conftest

DATA = Path(conftest.__file__).resolve().parent / "data"
spec = importlib.util.spec_from_file_location("derive", DATA / "derive.py")
derive = importlib.util.module_from_spec(spec)
spec.loader.exec_module(derive)


def test_small_data_matches_its_checksums_and_stays_small():
    assert derive.check() == []
    listed = {line.split("  ", 1)[1] for line in derive.SUMS.read_text().splitlines()}
    assert listed == set(derive.FILES)
    on_disk = {p.relative_to(DATA).as_posix() for p in DATA.rglob("*")
               if p.is_file() and "__pycache__" not in p.parts and p.parts[len(DATA.parts)] != "captures"}
    assert on_disk - listed == {"derive.py", "README.md", "SHA256SUMS"}
    assert sum((DATA / rel).stat().st_size for rel in listed) < 500_000


def test_capture_fixtures_are_small_credited_and_each_described():
    folder = DATA / "captures"  # one file per capture layout, written by us or cut from ../shared/data/real
    readme = (folder / "README.md").read_text()
    files = [p for p in folder.iterdir() if p.is_file()]
    fixtures = [p for p in files if p.suffix != ".py" and p.name != "README.md" and not p.name.startswith("LICENSE")]
    assert fixtures and all(f"`{p.name}`" in readme for p in fixtures), "every capture fixture has its README line"
    assert all(f"`{p.name}`" in readme for p in files if p.name.startswith("LICENSE")), "every licence is named"
    assert sum(p.stat().st_size for p in files) < 250_000


@pytest.mark.shared
def test_small_data_is_a_byte_copy_of_the_shared_data():
    for rel in derive.FILES:
        assert (DATA / rel).read_bytes() == (conftest.SHARED_DATA / rel).read_bytes(), rel


def test_missing_shared_data_skips_locally_and_fails_under_ci(monkeypatch, tmp_path):
    monkeypatch.setattr(conftest, "SHARED_DATA", tmp_path / "missing")
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception):
        conftest.require_shared_data()
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI is set"):
        conftest.require_shared_data()
    monkeypatch.setattr(conftest, "SHARED_DATA", tmp_path)
    assert conftest.require_shared_data() == tmp_path
