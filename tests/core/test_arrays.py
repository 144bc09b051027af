"""Array helpers give numpy's results."""

import numpy as np
import pytest

from converter.arrays import lengths, lexsort_ints, unique_ints


def test_unique_ints_is_np_unique():
    rng = np.random.default_rng(0)
    for x in (rng.integers(-50, 50, 1000), rng.integers(0, 2**62, (300, 3)), np.zeros(0, np.int64),
              np.array([7]), np.array([3, 3, 3], np.int32)):
        got = unique_ints(x)
        assert np.array_equal(got, np.unique(x)) and got.dtype == np.unique(x).dtype


@pytest.mark.parametrize("spread", [50, 2**40, 2**61])  # packed in one int64 key; 2^61: too wide, np.lexsort
def test_lexsort_ints_is_np_lexsort_ties_included(spread):
    rng = np.random.default_rng(3)
    path, half = rng.integers(0, 40, 4000), rng.integers(-spread, spread, 4000)  # many equal (path, half, flag)
    flag = rng.random(4000) < 0.3
    for keys in ((flag, half, path), (half, path), (path,), (flag, half, path[::-1])):
        assert np.array_equal(lexsort_ints(keys), np.lexsort(keys))
    assert len(lexsort_ints((path[:0], half[:0]))) == 0


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_lengths_are_np_linalg_norm_bit_for_bit(dtype):
    rng = np.random.default_rng(7)
    v = (rng.normal(size=(50, 40, 3, 2)) * rng.choice([1e-30, 1e-3, 1.0, 300.0, 1e30], (50, 40, 3, 1))).astype(dtype)
    v[0, 0, 0], v[0, 0, 1], v[0, 0, 2] = [np.inf, 1], [np.nan, 2], [-0.0, 0.0]
    with np.errstate(over="ignore", under="ignore"):
        want, got = np.linalg.norm(v, axis=-1), lengths(v)
    assert got.dtype == want.dtype and np.array_equal(got, want, equal_nan=True)
    assert np.array_equal(lengths(np.array([3.0, -4.0])), np.float64(5.0))
    with pytest.raises(ValueError):
        lengths(np.ones((4, 3)))
