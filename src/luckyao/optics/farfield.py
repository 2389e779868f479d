"""Far-field intensity of pupil phases: a pruned, zero-padded FFT.

For the field ``E = exp(i phi)`` on the ``n_valid`` samples of an N x N pupil
mask (zero elsewhere), zero-padded to M x M (M >= 2N), the far-field
intensity of unit total flux is ``I = |FFT_M(E)|^2 / (M^2 n_valid)``
(Parseval: ``sum |FFT_M(E)|^2 = M^2 n_valid``). An apodised pupil,
``E = t exp(i phi)`` with a transmission ``t`` on the samples, keeps the same
scale: its flux is ``sum t^2 / n_valid`` of the full pupil's (the flux lost is
in the image).

The 2D FFT runs as batches of 1D FFTs along contiguous rows (FFTW):

1. the field is written transposed, ``F[x, y] = E[y, x]`` (N x M, zero for
   ``y >= N``), and its N rows are transformed along ``y``;
2. in blocks of ``k_y`` rows, the transposed result goes into the first N
   columns of a block buffer (zero elsewhere), whose rows are transformed
   along ``x``, giving the rows of ``FFT_M(E)[k_y, k_x]`` whose power is added
   to the image.

Only the N rows that hold the pupil take the first pass, no pass is strided
and the block buffers stay in cache. FFTW_ESTIMATE plans are chosen without
timing, so the rounding, hence every result, is the same in every process.
An instance is not thread-safe (it owns its buffers).
"""

import numba
import numpy as np
import pyfftw

from .sincos import cos_sin

_BLOCK_ROWS = 64  # rows of the second pass per FFT call: 2 x 128 kB of buffers at M = 256


@numba.njit(cache=True, nogil=True)
def _scatter(cos, sin, sample, index, field):  # pragma: no cover (jit)
    """field[index[i]] = cos[s] + i sin[s] with s = sample[i] (index ascending: sequential writes)."""
    for i in range(index.size):
        s = sample[i]
        field[index[i]] = complex(cos[s], sin[s])


@numba.njit(cache=True, fastmath=True, nogil=True)
def _add_power(spectrum, scale, out, row0):  # pragma: no cover (jit)
    """out[row0 + i] += scale |spectrum[i]|^2 for the rows of out from row0 on."""
    for i in range(min(spectrum.shape[0], out.shape[0] - row0)):
        for j in range(out.shape[1]):
            z = spectrum[i, j]
            out[row0 + i, j] += scale * (z.real * z.real + z.imag * z.imag)


class FarField:
    """Unit-flux far-field intensities (M, M) of phases on the samples of ``mask`` (N, N)."""

    def __init__(self, mask: np.ndarray, fft_size: int):
        n, m = mask.shape[0], fft_size
        if mask.shape != (n, n) or m < 2 * n:
            raise ValueError(f"need a square mask and fft_size >= 2 N, got {mask.shape} and {m}")
        y, x = np.nonzero(mask)
        self.fft_size = m
        index = x * m + y  # sample (y, x) of E in the flat transposed field F
        self._sample = np.argsort(index).astype(np.int32)
        self._index = index[self._sample].astype(np.int32)
        self._scale = np.float32(1.0 / (m * m * y.size))
        self._cos = np.empty(y.size, dtype=np.float32)
        self._sin = np.empty(y.size, dtype=np.float32)
        field_t = pyfftw.zeros_aligned((n, m), dtype=np.complex64)
        rows = pyfftw.empty_aligned((n, m), dtype=np.complex64)
        block = pyfftw.zeros_aligned((min(_BLOCK_ROWS, m), m), dtype=np.complex64)
        self._spectrum = pyfftw.empty_aligned(block.shape, dtype=np.complex64)
        self._field_flat = field_t.reshape(-1)
        # (first row, its rows of the transposed first pass, where they go); the
        # last block may be partial: its other rows are stale and not added
        self._blocks = [
            (row0, rows.T[row0 : row0 + len(block)], block[: min(len(block), m - row0), :n])
            for row0 in range(0, m, len(block))
        ]
        flags = ("FFTW_ESTIMATE",)  # leaves the buffers untouched
        self._fft_y = pyfftw.FFTW(field_t, rows, axes=(1,), flags=flags, threads=1)
        self._fft_x = pyfftw.FFTW(block, self._spectrum, axes=(1,), flags=flags, threads=1)

    def accumulate(self, phase_rad: np.ndarray, out: np.ndarray, transmission: np.ndarray | None = None) -> None:
        """Add the intensity of each phase row (k, n_valid) [rad], float32, to ``out`` (k, M, M) float32;
        ``transmission`` (k, n_valid) float32 apodises each row (None: the full pupil)."""
        m = self.fft_size
        if out.shape != (len(phase_rad), m, m) or out.dtype != np.float32:
            raise ValueError(f"out must be float32 of shape {(len(phase_rad), m, m)}")
        if transmission is not None and np.shape(transmission) != np.shape(phase_rad):
            raise ValueError(f"transmission must have the phases' shape {np.shape(phase_rad)}")
        for k, (phase, image) in enumerate(zip(phase_rad, out)):
            cos_sin(phase, self._cos, self._sin)
            if transmission is not None:
                self._cos *= transmission[k]
                self._sin *= transmission[k]
            _scatter(self._cos, self._sin, self._sample, self._index, self._field_flat)
            self._fft_y.execute()
            for row0, source, head in self._blocks:
                np.copyto(head, source)
                self._fft_x.execute()
                _add_power(self._spectrum, self._scale, image, row0)
