"""The SVG number text: the vectorised formatter gives the strings of a value-by-value reference exactly."""

import numpy as np
import pytest

from converter.writers.svgtext import key_times, number, numbers, subpaths


def reference_number(x: float, decimals: int) -> str:
    """number() as it was written value by value: rounded, no trailing zeros, no leading zero, no -0."""
    s = f"{x:.{decimals}f}"
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    if s.startswith("0."):
        s = s[1:]
    elif s.startswith("-0."):
        s = "-" + s[2:]
    return "0" if s in ("-0", "", "-") else s


@pytest.mark.parametrize("decimals", range(8))
def test_numbers_match_number_one_by_one(decimals):
    rng = np.random.default_rng(decimals)
    values = np.concatenate([
        rng.normal(0, 1, 2000) * 10.0 ** rng.integers(-8, 6, 2000),  # every magnitude, both signs
        np.arange(-400, 401) / 2 ** rng.integers(1, 12),  # exact halves and quarters: the rounding ties
        np.arange(-50, 51) * 10.0 ** -decimals,  # on the grid itself
        [0.0, -0.0, 1e-12, -1e-12, 0.5, -0.5, 0.05, -0.05, 100.0, -100.0, 1e6, -1e6, 9.999999, -9.999999],
        [float("nan"), float("inf"), float("-inf")],
    ])
    got = numbers(values, decimals)
    assert got == [reference_number(v, decimals) for v in values.tolist()]
    assert [number(v, decimals) for v in values[::97].tolist()] == got[::97]
    assert "-0" not in got and all(s and s != "-" for s in got)


def test_numbers_of_nothing_and_of_a_matrix():
    assert numbers(np.zeros(0), 3) == []
    assert numbers(np.array([[1.5, -0.25], [0.0, 2.0]]), 2) == ["1.5", "-.25", "0", "2"]


def test_key_times_text_is_number_of_each_time():
    frames = np.arange(0, 301, 7)
    for dec in (2, 3, 4):
        assert key_times(frames, 300, dec) == [reference_number(round(f * 10**dec / 300) / 10**dec, dec)
                                                for f in frames.tolist()]


def reference_subpaths(rows: np.ndarray) -> list[str]:
    """subpaths() as the writer formatted it before it was compiled: one % call, ' -' trimmed to '-'."""
    one = "m" + " ".join(["%d"] * rows.shape[1]) + "z"
    return [(one % tuple(r)).replace(" -", "-") for r in rows.tolist()]


@pytest.mark.parametrize("width", [2, 6])
def test_subpaths_match_percent_formatting(width):
    rng = np.random.default_rng(width)
    rows = rng.integers(-10, 10, (3000, width)) * 10 ** rng.integers(0, 12, (3000, width))
    rows[::5] = 0
    rows[1::7] = -1
    rows[2] = [np.iinfo(np.int64).max] + [-(10 ** 17)] * (width - 1)
    assert subpaths(rows) == reference_subpaths(rows)
    assert subpaths(rows[:1]) == reference_subpaths(rows[:1])
    assert subpaths(rows[:0]) == []
    assert subpaths(np.array([[0, -5, 12, 0, -1, 3]])) == ["m0-5 12 0-1 3z"]
