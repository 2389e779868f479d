"""LLVM vector intrinsics: the register transpose moves every value where the scalar loops do;
the kernels' files follow the intrinsics they inline."""

import hashlib
from pathlib import Path

import numba
import numpy as np
import pytest

import luckyao
from luckyao.simd import LANES, transpose

INLINED = {
    "optics/propagation.py": ("optics/taps.py", "simd.py"),
    "wfs/kernels.py": ("simd.py",),
    "lucky/noise_streams.py": ("lucky/stream_vectors.py", "simd.py"),
    "lucky/radial_sums.py": ("simd.py",),
}
"""Files of cached kernels -> the files of the intrinsics those kernels inline."""


@numba.njit
def _blocks_transposed(values, starts, n, row, out):
    """out[x, r] = values[starts[r] + x] for x < n, r < starts.size, by LANES x LANES blocks."""
    for first in range(0, starts.size, LANES):
        for x in range(0, n, LANES):
            transpose(
                values, x, starts, first, min(LANES, starts.size - first), min(LANES, n - x), out, x * row + first, row
            )


@pytest.mark.parametrize("n, rows", [(16, 48), (12, 40), (20, 24), (1, 1), (33, 17)])
def test_transpose_moves_each_value_once(n, rows):
    rng = np.random.default_rng(n)
    values = rng.random(4096).astype(np.float32)
    starts = rng.integers(0, values.size - n, rows).astype(np.int32)
    out = np.full((n, rows), np.nan, dtype=np.float32)
    _blocks_transposed(values, starts, n, rows, out.reshape(-1))
    np.testing.assert_array_equal(out, values[starts[None, :] + np.arange(n)[:, None]])


@pytest.mark.parametrize("kernels, intrinsics", INLINED.items())
def test_kernel_files_carry_the_digest_of_their_intrinsics(kernels, intrinsics):
    """numba's disk cache keys a kernel by its own file: a file whose kernels inline intrinsics
    of other files carries their digest, so that an edit of theirs changes it (recompiles)."""
    root = Path(luckyao.__file__).parent
    digest = hashlib.sha256(b"".join((root / name).read_bytes() for name in intrinsics)).hexdigest()[:16]
    line = f"# intrinsics digest ({', '.join(intrinsics)}): {digest}"
    assert line in (root / kernels).read_text(), f"{kernels} needs the line: {line}"
