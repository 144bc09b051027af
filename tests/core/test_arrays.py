"""Array helpers give numpy's results."""

import numpy as np

from converter.arrays import unique_ints


def test_unique_ints_is_np_unique():
    rng = np.random.default_rng(0)
    for x in (rng.integers(-50, 50, 1000), rng.integers(0, 2**62, (300, 3)), np.zeros(0, np.int64),
              np.array([7]), np.array([3, 3, 3], np.int32)):
        got = unique_ints(x)
        assert np.array_equal(got, np.unique(x)) and got.dtype == np.unique(x).dtype
