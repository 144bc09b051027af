"""Array helpers give numpy's results."""

import numpy as np
import pytest

from converter.arrays import lexsort_ints, unique_ints


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
