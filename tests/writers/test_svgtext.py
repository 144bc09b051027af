"""The SVG number text: the vectorised formatter gives number()'s strings exactly."""

import numpy as np
import pytest

from converter.writers.svgtext import key_times, number, numbers


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
    assert got == [number(v, decimals) for v in values.tolist()]
    assert "-0" not in got and all(s and s != "-" for s in got)


def test_numbers_of_nothing_and_of_a_matrix():
    assert numbers(np.zeros(0), 3) == []
    assert numbers(np.array([[1.5, -0.25], [0.0, 2.0]]), 2) == ["1.5", "-.25", "0", "2"]


def test_key_times_text_is_number_of_each_time():
    frames = np.arange(0, 301, 7)
    for dec in (2, 3, 4):
        assert key_times(frames, 300, dec) == [number(round(f * 10**dec / 300) / 10**dec, dec)
                                                for f in frames.tolist()]
