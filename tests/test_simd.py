"""LLVM vector intrinsics: the register transpose moves every value where the scalar loops do."""

import numba
import numpy as np
import pytest

from luckyao.simd import LANES, transpose


@numba.njit
def _blocks_transposed(values, starts, n, row, out):
    """out[x, r] = values[starts[r] + x] for x < n, r < starts.size, by LANES x LANES blocks."""
    for first in range(0, starts.size, LANES):
        for x in range(0, n, LANES):
            transpose(values, x, starts, first, min(LANES, starts.size - first), min(LANES, n - x), out,
                      x * row + first, row)


@pytest.mark.parametrize("n, rows", [(16, 48), (12, 40), (20, 24), (1, 1), (33, 17)])
def test_transpose_moves_each_value_once(n, rows):
    rng = np.random.default_rng(n)
    values = rng.random(4096).astype(np.float32)
    starts = rng.integers(0, values.size - n, rows).astype(np.int32)
    out = np.full((n, rows), np.nan, dtype=np.float32)
    _blocks_transposed(values, starts, n, rows, out.reshape(-1))
    np.testing.assert_array_equal(out, values[starts[None, :] + np.arange(n)[:, None]])
