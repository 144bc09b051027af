"""Levels of articulation: Table 12.1 counts, grouping constraints, the symmetry rule, reduce/expand, fap-loa."""

from __future__ import annotations

import numpy as np
import pytest

from converter.errors import InputError
from converter.mpeg4 import loa
from converter.mpeg4.fap import read_fap, write_fap
from converter.mpeg4.standard import fap_table

TABLE_12_1 = {  # region: (high, medium, low, very low)
    "high level": (2, 2, 2, 2), "jaw": (31, 19, 12, 6), "eyeballs": (12, 8, 4, 1), "eyebrows": (8, 3, 2, 1),
    "cheeks": (4, 4, 1, 1), "nose": (4, 3, 0, 0), "ears": (4, 2, 2, 0),
}


def test_counts_match_table_12_1():
    assert [loa.fap_count(level) for level in loa.LEVELS] == [68, 44, 26, 14]
    for i, level in enumerate(loa.LEVELS):
        counts = loa.region_counts(level)
        for region, row in TABLE_12_1.items():
            assert counts[region] == row[i], (level, region)
        assert counts["head"] == 3


@pytest.mark.parametrize("level", loa.LEVELS)
def test_groups_obey_the_rules(level):
    table = fap_table()
    region_of = {f: r for r, faps in loa.REGIONS.items() for f in faps}
    seen = set()
    for g in loa.groups(level):
        assert not seen & set(g), "a FAP is in two groups"
        seen |= set(g)
        units = {table[f - 1].unit for f in g}
        assert len(units) == 1, g  # same FAPU
        assert len({region_of[f] for f in g}) == 1, g  # same region
        names = [table[f - 1].name for f in g]
        if any("_l_" in n or n.endswith("_l") for n in names) and any("_r_" in n for n in names):
            assert "_r_" in names[0], names  # symmetry: the right one controls
    if level == "high":
        assert seen == set(range(1, 69))


def test_reduce_and_expand():
    rng = np.random.default_rng(0)
    from converter.mpeg4.fap import FapStream

    values = rng.integers(-50, 50, (5, 68)).astype(float)
    mask = np.ones((5, 68), bool)
    mask[:, 6] = False  # stretch_r_cornerlip absent: its group takes the left value
    s = FapStream("x", 25, values, mask)
    low = loa.reduce(s, "low")
    assert low.mask.any(0).sum() == 26 and low.extra["loa"] == "low"
    np.testing.assert_array_equal(low.values[:, 6], values[:, 5])  # (7, 6, 53, 54) -> value of 6
    np.testing.assert_array_equal(low.values[:, 19], values[:, 19])  # (20, 19): right eyelid controls
    assert not low.mask[:, 18].any()
    back = loa.expand(read_fap(write_fap(low)))  # the level travels in a comment
    np.testing.assert_array_equal(back.values[:, 18], values[:, 19])
    np.testing.assert_array_equal(back.values[:, [5, 52, 53]], np.repeat(values[:, 5:6], 3, 1))
    assert not back.mask[:, 42].any()  # shift_tongue_tip removed at low
    high = loa.reduce(s, "high")
    np.testing.assert_array_equal(high.values, np.where(mask, values, 0))
    with pytest.raises(InputError, match="level of articulation"):
        loa.reduce(s, "ultra")


def test_sizes_shrink_on_xface_streams(small_data):
    for path in sorted((small_data / "mpeg4" / "xface").glob("*.fap")):
        s = read_fap(path)
        sizes = [len(write_fap(loa.reduce(s, level))) for level in loa.LEVELS]
        assert sizes[0] > sizes[1] > sizes[2] > sizes[3], path.name
        assert 0.4 < sizes[3] / sizes[0] < 0.8


def test_cli_fap_loa(small_data, tmp_path, capsys):
    from converter.cli import main

    out = tmp_path / "joy_low.fap"
    assert main(["fap-loa", str(small_data / "mpeg4" / "xface" / "joy.fap"), "--level", "low", "-o", str(out)]) == 0
    s = read_fap(out)
    assert s.extra["loa"] == "low" and s.n_frames == 108
    assert set(np.flatnonzero(s.mask.any(0)) + 1) <= {g[0] for g in loa.groups("low")}
    assert "LoA low" in capsys.readouterr().out
    bad = tmp_path / "bad.fap"
    bad.write_text("2.1 x 25 1\n0 0 1\n0 5\n")
    assert main(["fap-loa", str(bad), "--level", "low", "-o", str(tmp_path / "o.fap")]) == 2
    assert "line 2" in capsys.readouterr().err
    assert not (tmp_path / "o.fap").exists()
    with pytest.raises(SystemExit):
        main(["fap-loa", str(bad), "--level", "ultra", "-o", str(tmp_path / "o.fap")])
