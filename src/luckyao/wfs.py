"""Open-loop Shack-Hartmann wavefront sensor, physical optics, batched.

Model (all sub-apertures of all beacons at once, no Python loop over them):

* The pupil grid has ``n_s`` samples per sub-aperture (``n_s`` even, the
  closest to ``d / (lambda / FOV)``), so ``dx = d / n_s`` and every fully
  illuminated sub-aperture is identical. Its FFT is periodic in angle with
  period ``F = lambda / dx`` (~ the detector field ``n_pixels * pixel_scale``).
* Sub-aperture intensity ``I = |FFT_M(A exp(i phi))|^2`` (Goodman, *Fourier
  Optics*, ch. 4) on ``M >= 2 n_s`` samples is a trigonometric polynomial of
  period ``F``: its Fourier coefficients ``c_q`` (``rfft2``) are exact, so
  the LGS spot (uplink spot and elongation) is applied exactly by OTF
  products ``c_q * g(q / F)`` and the detector pixels are integrated exactly
  (``P = Re(E_y c E_x^T)``, ``E_jq = integral over pixel j of exp(2 pi i q a / F)``).
  Light beyond the field wraps periodically (a sub-aperture without field
  stop, fed by identical neighbours).
* Sign convention as in :mod:`luckyao.imaging`: a phase ``2 pi theta x / lambda``
  moves the spot by ``+theta``; slopes have the sign of the phase gradient.
* Centre of gravity over the ``n_pixels^2`` pixels gives the mean angle of
  arrival [rad] = mean gradient of the optical path over the sub-aperture
  (Primot 2003 / Teague) when the spot is resolved by the pixels; with 0.84"
  pixels and a diffraction-limited spot it is quad-cell like (non-linear).

Arrays: phases ``(..., n, n)`` indexed ``[y, x]``; slopes ``(n_beacons, 2, n_valid)``
with axis 1 = (x, y) [rad]; images ``(n_beacons, n_valid, n_pixels, n_pixels)``.
"""

from dataclasses import dataclass
from functools import cached_property, lru_cache
from types import SimpleNamespace

import numba
import numpy as np
import scipy.fft

from .lgs import LgsConfig, altitude_limits_m, altitude_profile, elongation_offsets_rad
from .pupil import PupilGrid, Telescope
from .units import ARCSEC_RAD


@dataclass(frozen=True, eq=False)
class ShackHartmann:
    """Geometry of one SH WFS (shared by all beacons of an asterism).

    ``n_subapertures`` across the telescope diameter, ``n_pixels`` x
    ``n_pixels`` detector pixels of ``pixel_scale_arcsec`` per sub-aperture at
    ``wavelength_m``; a sub-aperture is valid when its illuminated fraction is
    ``>= min_illumination``. ``launch_diameter_m`` sizes the uplink grid.
    """

    telescope: Telescope
    n_subapertures: int
    wavelength_m: float
    n_pixels: int = 4
    pixel_scale_arcsec: float = 0.84
    min_illumination: float = 0.5
    launch_diameter_m: float = 0.35

    # --- sampling -----------------------------------------------------------
    @property
    def pixel_scale_rad(self) -> float:
        return self.pixel_scale_arcsec * ARCSEC_RAD

    @property
    def subaperture_m(self) -> float:
        """Sub-aperture side ``d`` [m] in the pupil."""
        return self.telescope.diameter_m / self.n_subapertures

    @cached_property
    def samples_per_subaperture(self) -> int:
        """``n_s``: even number of pupil samples per sub-aperture side."""
        ideal = self.subaperture_m * self.n_pixels * self.pixel_scale_rad / self.wavelength_m
        return max(2, 2 * int(round(ideal / 2)))

    @cached_property
    def grid(self) -> PupilGrid:
        """Pupil grid on which the caller provides each beacon's phase (n, n)."""
        n_s = self.samples_per_subaperture
        return PupilGrid(n_pix=self.n_subapertures * n_s, dx_m=self.subaperture_m / n_s)

    @property
    def period_rad(self) -> float:
        """Angular period ``F = lambda / dx`` of the sub-aperture FFT [rad]."""
        return self.wavelength_m / self.grid.dx_m

    @cached_property
    def launch_grid(self) -> PupilGrid:
        """Grid (same spacing as ``grid``) for the uplink phase over the launch aperture."""
        return Telescope(self.launch_diameter_m, 0.0).grid_for(self.grid.dx_m)

    @cached_property
    def launch_mask(self) -> np.ndarray:
        return Telescope(self.launch_diameter_m, 0.0).mask(self.launch_grid)

    @cached_property
    def fft_size(self) -> int:
        """``M``: FFT samples per period, >= 2x the sub-aperture and launch widths."""
        m = max(2 * self.samples_per_subaperture, 2 * self.launch_grid.n_pix)
        return m + m % 2

    # --- sub-apertures --------------------------------------------------------
    @cached_property
    def mask(self) -> np.ndarray:
        return self.telescope.mask(self.grid)

    @cached_property
    def illumination(self) -> np.ndarray:
        """Illuminated fraction of each sub-aperture, shape (N, N) [y, x]."""
        n, n_s = self.n_subapertures, self.samples_per_subaperture
        return self.mask.reshape(n, n_s, n, n_s).mean(axis=(1, 3))

    @cached_property
    def valid(self) -> np.ndarray:
        """Valid sub-apertures, bool (N, N) [y, x]."""
        return self.illumination >= self.min_illumination

    @cached_property
    def n_valid(self) -> int:
        return int(self.valid.sum())

    @cached_property
    def subaperture_index(self) -> np.ndarray:
        """Integer ``(iy, ix)`` (n_valid, 2) of the valid sub-apertures (row-major order)."""
        return np.argwhere(self.valid)

    @cached_property
    def subaperture_xy_m(self) -> np.ndarray:
        """Centres ``(x, y)`` (n_valid, 2) [m] of the valid sub-apertures."""
        centre = (self.subaperture_index - (self.n_subapertures - 1) / 2) * self.subaperture_m
        return centre[:, ::-1].copy()

    @cached_property
    def amplitude(self) -> np.ndarray:
        """Pupil transmission of each valid sub-aperture (n_valid, n_s, n_s) float32."""
        return self._split(self.mask.astype(np.float32))

    def _split(self, grid_values: np.ndarray) -> np.ndarray:
        """(..., n, n) grid -> (..., n_valid, n_s, n_s) sub-aperture blocks (copy)."""
        n, n_s = self.n_subapertures, self.samples_per_subaperture
        lead = grid_values.shape[:-2]
        blocks = grid_values.reshape(*lead, n, n_s, n, n_s).swapaxes(-3, -2)
        blocks = blocks.reshape(*lead, n * n, n_s, n_s)
        flat = self.subaperture_index[:, 0] * n + self.subaperture_index[:, 1]
        return blocks[..., flat, :, :]

    # --- Fourier sampling of the spot -----------------------------------------
    @cached_property
    def harmonics(self) -> tuple[np.ndarray, np.ndarray]:
        """Spatial frequencies ``(f_y (M,), f_x (M//2+1,))`` [cycles/rad] of ``rfft2``."""
        m = self.fft_size
        return (np.fft.fftfreq(m) * m / self.period_rad,
                np.fft.rfftfreq(m) * m / self.period_rad)

    @cached_property
    def pixel_centres_rad(self) -> np.ndarray:
        """Pixel centres (n_pixels,) [rad] about the sub-aperture axis."""
        return (np.arange(self.n_pixels) - (self.n_pixels - 1) / 2) * self.pixel_scale_rad

    @cached_property
    def _pixel_integrals(self) -> tuple[np.ndarray, np.ndarray]:
        """``E_y`` (n_pix, M) and weighted ``E_x`` (n_pix, M//2+1), complex64.

        ``E[j, q] = integral over pixel j of exp(2 pi i q u) du`` with ``u`` the
        angle in periods; the Nyquist harmonic (zero for a band-limited
        intensity) is dropped, ``rfft`` half-plane columns weighted 2.
        """
        m = self.fft_size
        lower = (np.arange(self.n_pixels) - self.n_pixels / 2) * self.pixel_scale_rad
        lower = lower / self.period_rad
        upper = lower + self.pixel_scale_rad / self.period_rad

        def integral(q):
            q = q[None, :]
            with np.errstate(invalid="ignore", divide="ignore"):
                value = (np.exp(2j * np.pi * q * upper[:, None])
                         - np.exp(2j * np.pi * q * lower[:, None])) / (2j * np.pi * q)
            return np.where(q == 0, (upper - lower)[:, None], value)

        q_y = np.fft.fftfreq(m) * m
        e_y = integral(q_y)
        e_y[:, q_y == -m / 2] = 0.0
        q_x = np.fft.rfftfreq(m) * m
        weight = np.where(q_x == 0, 1.0, 2.0)
        weight[q_x == m / 2] = 0.0
        e_x = integral(q_x) * weight
        return e_y.astype(np.complex64), e_x.astype(np.complex64)


# --- per-step physics ---------------------------------------------------------
@numba.njit(nogil=True)
def _fill_fields(cos_phase, sin_phase, amplitude, out):  # pragma: no cover (jit)
    """out[b, v] = A (cos + i sin), zero-padded to (M, M); one pass, no temporaries."""
    n_b, n_v, m, _ = out.shape
    n_s = amplitude.shape[-1]
    for b in range(n_b):
        for v in range(n_v):
            for i in range(n_s):
                for j in range(n_s):
                    a = amplitude[v, i, j]
                    out[b, v, i, j] = complex(a * cos_phase[b, v, i, j], a * sin_phase[b, v, i, j])
                for j in range(n_s, m):
                    out[b, v, i, j] = 0
            for i in range(n_s, m):
                for j in range(m):
                    out[b, v, i, j] = 0


@numba.njit(nogil=True)
def _add_power(spectrum, out, overwrite):  # pragma: no cover (jit)
    """out (+)= |spectrum|^2 elementwise (float32)."""
    flat_s = spectrum.reshape(-1)
    flat_o = out.reshape(-1)
    for k in range(flat_s.size):
        z = flat_s[k]
        power = z.real * z.real + z.imag * z.imag
        flat_o[k] = power if overwrite else flat_o[k] + power


def intensity_samples(wfs: ShackHartmann, phase_rad: np.ndarray, phase_wavelength_m: float,
                      out: np.ndarray | None = None) -> np.ndarray:
    """Sub-aperture intensities ``|FFT_M(A exp(i phi))|^2``, no LGS spot.

    ``phase_rad`` (n_beacons, n, n) on ``wfs.grid`` [rad at ``phase_wavelength_m``]
    -> (n_beacons, n_valid, M, M) float32, unshifted (sample ``k`` at angle
    ``k F / M``), unnormalised (sum = ``M^2`` x illuminated samples). With
    ``out`` (float32, that shape) the intensity is added to it in place.
    """
    m = wfs.fft_size
    n_s = wfs.samples_per_subaperture
    phase = np.asarray(phase_rad, dtype=np.float32)
    if phase.ndim != 3:
        raise ValueError("phase must be (n_beacons, n, n)")
    phase = wfs._split(phase)  # copy (n_beacons, n_valid, n_s, n_s)
    phase *= np.float32(phase_wavelength_m / wfs.wavelength_m)
    field = np.empty((phase.shape[0], wfs.n_valid, m, m), dtype=np.complex64)
    _fill_fields(np.cos(phase), np.sin(phase), wfs.amplitude, field)
    # pruned 2-D FFT: y over the n_s non-zero columns, then x over all rows, in place
    scipy.fft.fft(field[..., :n_s], axis=-2, overwrite_x=True)
    scipy.fft.fft(field, axis=-1, overwrite_x=True)
    if out is None:
        out = np.empty(field.shape, dtype=np.float32)
        _add_power(field, out, True)
    else:
        _add_power(field, out, False)
    return out


def intensity_spectra(wfs: ShackHartmann, intensity: np.ndarray) -> np.ndarray:
    """Fourier coefficients (..., n_valid, M, M//2+1) complex64 of intensities.

    ``intensity`` (..., n_valid, M, M) from :func:`intensity_samples` (or a sum
    of ``T`` of them divided by ``T``); the (0, 0) coefficient is the
    illuminated fraction (flux of a full sub-aperture = 1).
    """
    m = wfs.fft_size
    coefficients = scipy.fft.rfft2(intensity)
    coefficients *= np.float32(1.0 / (m * m * wfs.samples_per_subaperture**2))
    return coefficients


def elongation_otf(wfs: ShackHartmann, offsets_rad: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """OTF (n_valid, M, M//2+1) complex64 of line spots.

    ``offsets_rad`` (n_valid, n_z, 2) [rad, (x, y)], ``weights`` (n_z,) summing
    to 1: ``g(f) = sum_z w_z exp(-2 pi i f . delta_z)`` (Fourier transform of
    a sum of points).
    """
    f_y, f_x = wfs.harmonics
    otf = np.zeros((offsets_rad.shape[0], f_y.size, f_x.size), dtype=np.complex128)
    for k in range(offsets_rad.shape[1]):  # loop over altitude samples only
        dx = offsets_rad[:, k, 0][:, None, None]
        dy = offsets_rad[:, k, 1][:, None, None]
        otf += weights[k] * np.exp(-2j * np.pi * (f_y[None, :, None] * dy + f_x[None, None, :] * dx))
    return otf.astype(np.complex64)


def lgs_elongation_otf(wfs: ShackHartmann, config: LgsConfig) -> np.ndarray:
    """Static elongation OTF (n_valid, M, M//2+1) for an LGS asterism.

    Altitudes are sampled finely enough that adjacent points are < 1/8 of an
    FFT sample apart on the sky (see :func:`luckyao.lgs.altitude_profile`).
    """
    z_low, z_high = altitude_limits_m(config)
    span = 1 / z_low - 1 / z_high
    baseline = np.hypot(*(wfs.subaperture_xy_m - config.launch_xy_m).T).max(initial=0.0)
    sample_rad = wfs.period_rad / wfs.fft_size
    n_z = int(np.clip(np.ceil(16 * baseline * span / sample_rad), 8, 2048))
    z_m, weights = altitude_profile(config, n_z)
    offsets = elongation_offsets_rad(wfs.subaperture_xy_m, config.launch_xy_m,
                                     config.height_m, z_m)
    return elongation_otf(wfs, offsets, weights)


def uplink_otf(wfs: ShackHartmann, uplink_phase_rad: np.ndarray,
               phase_wavelength_m: float) -> np.ndarray:
    """OTF (..., M, M//2+1) complex64 of the laser spot on the sky.

    The spot is ``|FFT(A_launch exp(i phi_up))|^2`` (far field of the focused
    beam, angles seen from the launch = from the telescope), with
    ``uplink_phase_rad`` (..., n_l, n_l) on ``wfs.launch_grid`` [rad at
    ``phase_wavelength_m``]. It carries the uplink tip-tilt (jitter) and
    broadening; normalised to unit flux.
    """
    m = wfs.fft_size
    phase = np.asarray(uplink_phase_rad, dtype=np.float32)
    phase = phase * np.float32(phase_wavelength_m / wfs.wavelength_m)
    field = wfs.launch_mask * (np.cos(phase) + 1j * np.sin(phase)).astype(np.complex64)
    spectrum = scipy.fft.fft2(field, s=(m, m))
    spot = spectrum.real**2 + spectrum.imag**2
    otf = scipy.fft.rfft2(spot)
    return otf / otf[..., :1, :1].real


def gaussian_otf(wfs: ShackHartmann, fwhm_rad: float) -> np.ndarray:
    """OTF (M, M//2+1) of a round Gaussian spot of ``fwhm_rad`` (e.g. extra blur)."""
    f_y, f_x = wfs.harmonics
    sigma = fwhm_rad / (2 * np.sqrt(2 * np.log(2)))
    f2 = f_y[:, None] ** 2 + f_x[None, :] ** 2
    return np.exp(-2 * np.pi**2 * sigma**2 * f2).astype(np.complex64)


def pixel_images(wfs: ShackHartmann, spectra: np.ndarray) -> np.ndarray:
    """Detector images (..., n_pixels, n_pixels) float32 [y, x] from spectra.

    Exact integration over the pixels of the band-limited intensity whose
    Fourier coefficients are ``spectra`` (..., M, M//2+1); values are
    fractions of a full sub-aperture's flux.
    """
    e_y, e_x = wfs._pixel_integrals
    return np.matmul(np.matmul(e_y, spectra), e_x.T).real.astype(np.float32)


# --- fused exposure kernel ------------------------------------------------------
# Sub-apertures are processed in "lanes": blocks of _LANES of them (one beacon
# each) are stored innermost (..., _LANES) so that every FFT butterfly, power
# accumulation and OTF product is one SIMD loop over the lanes; the pixel
# integration is then two complex matrix products (BLAS) for all of them.
# The 2-D transforms are radix-2 on N = 2^k >= 2 n_in samples (N may differ
# from ``fft_size``: the Fourier coefficients of the intensity are those of
# the autocorrelation of the field, independent of the padding as long as
# N >= 2 n_in). The forward transform is decimation in frequency (natural in,
# bit-reversed out), the intensity transform decimation in time (bit-reversed
# in, natural out), so no bit reversal is ever done; the zero-padded half of
# the field is pruned (the first DIF stage is a copy and a twiddle), and only
# the p = 0..N/2-1 half-plane of the intensity spectrum is computed.
# 48 lanes: long enough SIMD loops (16 were ~2x slower) and no padding for the
# 8x8 WFS (48 valid sub-apertures).
_LANES = 48


def _next_pow2(n: int) -> int:
    return 1 << max(1, int(n - 1).bit_length())


def _twiddles(n_fft: int) -> tuple[np.ndarray, np.ndarray]:
    w = np.exp(-2j * np.pi * np.arange(n_fft // 2) / n_fft)
    return w.real.astype(np.float32), w.imag.astype(np.float32)


# The kernels work on flat float32 buffers with unsigned offsets and are
# compiled per transform size (``n_fft``, ``n_in`` and the twiddles are
# compile-time constants): that is what lets LLVM vectorise the lane loops
# (signed 2-D indexing or a run-time size keeps them scalar, 5-8x slower).
_U = numba.uint64


@lru_cache(maxsize=None)
def _lane_kernels(n_fft: int, n_in: int, lanes: int) -> SimpleNamespace:
    """JIT kernels for transforms of ``n_fft`` (power of 2) samples of ``n_in``
    inputs, ``lanes`` sub-apertures at a time."""
    half = n_fft // 2
    n_rows = max(n_in, half)
    block = n_in * n_in * lanes
    tw_re, tw_im = _twiddles(n_fft)
    assert n_in <= half and n_fft >= 4

    @numba.njit(nogil=True, inline="always")
    def dif(re, im):  # pragma: no cover (jit)
        """In-place radix-2 DIF stages N/4, .., 1 (the N/2 stage is in load_padded)."""
        h = half // 2
        while h >= 1:
            step = n_fft // (2 * h)
            for start in range(0, n_fft, 2 * h):
                for k in range(h):
                    wr = tw_re[k * step]
                    wi = tw_im[k * step]
                    o0 = _U((start + k) * lanes)
                    o1 = _U((start + k + h) * lanes)
                    for lane in range(lanes):
                        ar = re[o0 + lane]
                        ai = im[o0 + lane]
                        br = re[o1 + lane]
                        bi = im[o1 + lane]
                        re[o0 + lane] = ar + br
                        im[o0 + lane] = ai + bi
                        dr = ar - br
                        di = ai - bi
                        re[o1 + lane] = dr * wr - di * wi
                        im[o1 + lane] = dr * wi + di * wr
            h //= 2

    @numba.njit(nogil=True, inline="always")
    def butterfly(re, im, o0, o1, wr, wi):  # pragma: no cover (jit)
        """One radix-2 DIT butterfly on every lane: (a, b) -> (a + w b, a - w b)."""
        for lane in range(lanes):
            br = re[o1 + lane]
            bi = im[o1 + lane]
            tr = br * wr - bi * wi
            ti = br * wi + bi * wr
            ar = re[o0 + lane]
            ai = im[o0 + lane]
            re[o0 + lane] = ar + tr
            im[o0 + lane] = ai + ti
            re[o1 + lane] = ar - tr
            im[o1 + lane] = ai - ti

    @numba.njit(nogil=True, inline="always")
    def dit(re, im, lower_half_only):  # pragma: no cover (jit)
        """In-place radix-2 DIT (bit-reversed in, natural out); with
        ``lower_half_only`` the last stage only writes outputs 0..N/2-1."""
        h = 1
        while h < half:
            step = n_fft // (2 * h)
            for start in range(0, n_fft, 2 * h):
                for k in range(h):
                    wr = tw_re[k * step]
                    wi = tw_im[k * step]
                    o0 = _U((start + k) * lanes)
                    o1 = _U((start + k + h) * lanes)
                    butterfly(re, im, o0, o1, wr, wi)
            h *= 2
        for k in range(half):
            wr = tw_re[k]
            wi = tw_im[k]
            o0 = _U(k * lanes)
            o1 = _U((k + half) * lanes)
            if lower_half_only:
                for lane in range(lanes):
                    br = re[o1 + lane]
                    bi = im[o1 + lane]
                    re[o0 + lane] += br * wr - bi * wi
                    im[o0 + lane] += br * wi + bi * wr
            else:
                butterfly(re, im, o0, o1, wr, wi)

    @numba.njit(nogil=True, inline="always")
    def load_padded(src_re, src_im, src_offset, src_stride, re, im):  # pragma: no cover
        """First DIF stage of a zero-padded input: buffer rows y and y + N/2 from
        the ``n_in`` source rows at ``src_offset + y src_stride``."""
        for y in range(n_in):
            wr = tw_re[y]
            wi = tw_im[y]
            s = _U(src_offset + y * src_stride)
            o0 = _U(y * lanes)
            o1 = _U((y + half) * lanes)
            for lane in range(lanes):
                fr = src_re[s + lane]
                fi = src_im[s + lane]
                re[o0 + lane] = fr
                im[o0 + lane] = fi
                re[o1 + lane] = fr * wr - fi * wi
                im[o1 + lane] = fr * wi + fi * wr
        for y in range(n_in, half):
            o0 = _U(y * lanes)
            o1 = _U((y + half) * lanes)
            for lane in range(lanes):
                re[o0 + lane] = 0.0
                im[o0 + lane] = 0.0
                re[o1 + lane] = 0.0
                im[o1 + lane] = 0.0

    @numba.njit(nogil=True)
    def buffers():  # pragma: no cover (jit)
        return (np.empty(n_in * lanes, np.float32), np.empty(n_in * lanes, np.float32),
                np.empty(n_fft * lanes, np.float32), np.empty(n_fft * lanes, np.float32),
                np.empty(n_fft * n_rows * lanes, np.float32),
                np.empty(n_fft * n_rows * lanes, np.float32),
                np.empty(n_fft * n_fft * lanes, np.float32))

    @numba.njit(nogil=True)
    def chunk_spectrum(cos_p, sin_p, amp, n_steps, n_chunks, chunk, amp_chunk, work,
                       otf, otf_chunk, spot, beacon, c):  # pragma: no cover (jit)
        """Half-plane spectrum of sum_t |FFT(amp exp(i phi_t))|^2 times the spot OTF.

        Flat inputs: ``cos_p``/``sin_p`` (T, n_chunks, n_in, n_in, L) [y, x],
        ``amp`` (n_amp, n_in, n_in, L). Writes
        ``c[q, chunk, p, lane] = C[q, p, lane] otf[q, otf_chunk, p, lane] spot[beacon, q, p]``
        (complex64, c (N, n_chunks, N/2, L), otf (N, n_otf, N/2, L), spot
        (n_b, N, N/2)) with C = N^2 x the autocorrelation of the field.
        """
        col_re, col_im, buf_re, buf_im, rows_re, rows_im, power = work
        n_otf = otf.size // (n_fft * half * lanes)
        for i in range(n_fft * n_fft * lanes):
            power[i] = 0.0
        a0 = _U(amp_chunk * block)
        for t in range(n_steps):
            f0 = _U((t * n_chunks + chunk) * block)
            # y transform of the n_in non-zero columns (bit-reversed ky)
            for x in range(n_in):
                for y in range(n_in):
                    o = _U((y * n_in + x) * lanes)
                    d = _U(y * lanes)
                    for lane in range(lanes):
                        a = amp[a0 + o + lane]
                        col_re[d + lane] = a * cos_p[f0 + o + lane]
                        col_im[d + lane] = a * sin_p[f0 + o + lane]
                load_padded(col_re, col_im, 0, lanes, buf_re, buf_im)
                dif(buf_re, buf_im)
                for ky in range(n_fft):
                    o = _U((ky * n_rows + x) * lanes)
                    d = _U(ky * lanes)
                    for lane in range(lanes):
                        rows_re[o + lane] = buf_re[d + lane]
                        rows_im[o + lane] = buf_im[d + lane]
            # x transform of every row, |.|^2 accumulated (bit-reversed ky, kx)
            for ky in range(n_fft):
                load_padded(rows_re, rows_im, ky * n_rows * lanes, lanes, buf_re, buf_im)
                dif(buf_re, buf_im)
                o = _U(ky * n_fft * lanes)
                for i in range(n_fft * lanes):
                    power[o + i] += buf_re[i] * buf_re[i] + buf_im[i] * buf_im[i]
        # forward DFT of the (real) intensity: x (p < N/2 only), then y
        for ky in range(n_fft):
            o = _U(ky * n_fft * lanes)
            for i in range(n_fft * lanes):
                buf_re[i] = power[o + i]
                buf_im[i] = 0.0
            dit(buf_re, buf_im, True)
            o = _U(ky * n_rows * lanes)
            for i in range(half * lanes):
                rows_re[o + i] = buf_re[i]
                rows_im[o + i] = buf_im[i]
        for p in range(half):
            for ky in range(n_fft):
                o = _U((ky * n_rows + p) * lanes)
                d = _U(ky * lanes)
                for lane in range(lanes):
                    buf_re[d + lane] = rows_re[o + lane]
                    buf_im[d + lane] = rows_im[o + lane]
            dit(buf_re, buf_im, False)
            for q in range(n_fft):
                o = _U(((q * n_chunks + chunk) * half + p) * lanes)
                g = _U(((q * n_otf + otf_chunk) * half + p) * lanes)
                s = spot[(beacon * n_fft + q) * half + p]
                d = _U(q * lanes)
                for lane in range(lanes):
                    c[o + lane] = complex(buf_re[d + lane], buf_im[d + lane]) * (otf[g + lane] * s)

    @numba.njit(nogil=True)
    def spectra(cos_p, sin_p, amp, n_steps, n_chunks, otf, spot, out):  # pragma: no cover
        """Spectra x OTFs (N, n_chunks, N/2, L) complex64 of every chunk (see
        chunk_spectrum); chunk ``c`` uses amplitude and ``otf`` block ``c % n_amp``
        and the ``spot`` of beacon ``c // n_amp``."""
        work = buffers()
        n_amp = amp.size // block
        for chunk in range(n_chunks):
            chunk_spectrum(cos_p, sin_p, amp, n_steps, n_chunks, chunk, chunk % n_amp, work,
                           otf, chunk % n_amp, spot, chunk // n_amp, out)

    return SimpleNamespace(spectra=spectra)


@numba.njit(nogil=True)
def _gather_phase(phase, n_b, n, beacon, offset_y, offset_x, ratio, n_steps, n_chunks, n_in,
                  lanes, out):  # pragma: no cover (jit)
    """out[t, c, y, x, l] = ratio * phase[t, beacon[c, l], oy[c, l] + y, ox[c, l] + x] (flat)."""
    for t in range(n_steps):
        for c in range(n_chunks):
            for lane in range(lanes):
                b = beacon[c * lanes + lane]
                src0 = ((t * n_b + b) * n + offset_y[c * lanes + lane]) * n \
                    + offset_x[c * lanes + lane]
                dst0 = (t * n_chunks + c) * n_in * n_in * lanes + lane
                for y in range(n_in):
                    s = _U(src0 + y * n)
                    d = _U(dst0 + y * n_in * lanes)
                    for x in range(n_in):
                        out[d + _U(x * lanes)] = ratio * phase[s + _U(x)]


@numba.njit(nogil=True)
def _gather_elongation(elongation, q_index, n_p, out):  # pragma: no cover (jit)
    """out[i, v // L, p, v % L] = elongation[v, q_index[i], p] (0 where q_index < 0,
    p >= n_p or v padded); ``out`` (N, chunks_per_beacon, N/2, L) complex64."""
    n_v = elongation.shape[0]
    lanes = out.shape[3]
    out[:] = 0.0
    for v in range(n_v):
        for i in range(q_index.size):
            if q_index[i] >= 0:
                for p in range(n_p):
                    out[i, v // lanes, p, v % lanes] = elongation[v, q_index[i], p]


@dataclass(frozen=True, eq=False)
class _LanePlan:
    """Static lane layout of one source (downlink sub-apertures or launch apertures)."""

    n_in: int
    n_fft: int
    lanes: int
    beacon: np.ndarray      # (n_chunks, L) int64
    offset_y: np.ndarray    # (n_chunks, L) int64
    offset_x: np.ndarray    # (n_chunks, L) int64
    amp: np.ndarray         # (n_amp, n_in, n_in, L) float32
    chunks_per_beacon: int

    @property
    def n_chunks(self) -> int:
        return self.beacon.shape[0]

    def trig(self, phase: np.ndarray, ratio: float) -> tuple[np.ndarray, np.ndarray]:
        """cos and sin (T, n_chunks, n_in, n_in, L) float32 of the gathered phases."""
        n_steps, n_b, n, _ = phase.shape
        lanes = np.empty(n_steps * self.n_chunks * self.n_in * self.n_in * self.lanes,
                         dtype=np.float32)
        _gather_phase(phase.reshape(-1), n_b, n, self.beacon.reshape(-1),
                      self.offset_y.reshape(-1), self.offset_x.reshape(-1), np.float32(ratio),
                      n_steps, self.n_chunks, self.n_in, self.lanes, lanes)
        return np.cos(lanes), np.sin(lanes, out=lanes)


def _downlink_plan(wfs: ShackHartmann, n_beacons: int) -> _LanePlan:
    lanes = _LANES
    n_s = wfs.samples_per_subaperture
    n_v = wfs.n_valid
    per_beacon = -(-n_v // lanes)
    v = np.arange(per_beacon * lanes)
    index = wfs.subaperture_index[np.minimum(v, n_v - 1)]
    offset_y = np.tile((index[:, 0] * n_s).reshape(per_beacon, lanes), (n_beacons, 1))
    offset_x = np.tile((index[:, 1] * n_s).reshape(per_beacon, lanes), (n_beacons, 1))
    beacon = np.repeat(np.arange(n_beacons), per_beacon)[:, None] * np.ones(lanes, np.int64)
    amp = np.zeros((per_beacon * lanes, n_s, n_s), dtype=np.float32)
    amp[:n_v] = wfs.amplitude
    amp = np.ascontiguousarray(amp.reshape(per_beacon, lanes, n_s, n_s).transpose(0, 2, 3, 1))
    n_fft = _next_pow2(2 * n_s)
    return _LanePlan(n_s, n_fft, lanes, beacon.astype(np.int64),
                     offset_y.astype(np.int64), offset_x.astype(np.int64), amp, per_beacon)


def _signed_harmonics(n_fft: int) -> np.ndarray:
    """Integer harmonic of each natural-order DFT index (fftfreq order)."""
    return np.fft.fftfreq(n_fft, 1.0 / n_fft).round().astype(np.int64)


@dataclass(frozen=True, eq=False)
class _ExposurePlan:
    down: _LanePlan
    q_index: np.ndarray     # (N,) index of each internal harmonic on the fft_size grid, -1 if none
    ey: np.ndarray          # (n_pix, N) complex64 pixel integrals E_y on the internal grid
    ex: np.ndarray          # (n_pix, N/2) complex64 weighted E_x
    no_elongation: np.ndarray  # (N, chunks_per_beacon, N/2, L) complex64 unit OTF


def _exposure_plan(wfs: ShackHartmann, n_beacons: int) -> _ExposurePlan:
    plans = wfs.__dict__.setdefault("_exposure_plans", {})
    if n_beacons in plans:
        return plans[n_beacons]
    down = _downlink_plan(wfs, n_beacons)
    m = wfs.fft_size
    n_fft, half = down.n_fft, down.n_fft // 2
    q = _signed_harmonics(n_fft)
    inside = (q > -m / 2) & (q < m / 2)
    q_index = np.where(inside, q % m, -1)
    e_y, e_x = wfs._pixel_integrals
    ey = np.where(inside[None, :], e_y[:, np.where(inside, q % m, 0)], 0)
    ex = np.zeros((wfs.n_pixels, half), dtype=np.complex64)
    n_p = min(half, m // 2 + 1)
    ex[:, :n_p] = e_x[:, :n_p]
    no_elongation = np.ones((n_fft, down.chunks_per_beacon, half, down.lanes), np.complex64)
    plan = _ExposurePlan(down, q_index.astype(np.int64), ey.astype(np.complex64),
                         ex.astype(np.complex64), no_elongation)
    plans[n_beacons] = plan
    return plan


def _exposure_uplink_otf(wfs: ShackHartmann, plan: _ExposurePlan, uplink: np.ndarray,
                         ratio: float) -> np.ndarray:
    """Exposure-mean uplink OTF (n_beacons, N, N/2) complex64 on the downlink harmonics.

    As :func:`uplink_otf`, but the steps' spots are summed before the single
    transform and the sum normalised to unit flux: the mean of the steps'
    unit-flux OTFs, since every step's spot has the same flux (Parseval,
    phase-only changes).
    """
    m = wfs.fft_size
    phase = uplink * np.float32(ratio)
    field = wfs.launch_mask * (np.cos(phase) + 1j * np.sin(phase)).astype(np.complex64)
    spectrum = scipy.fft.fft2(field, s=(m, m), overwrite_x=True)
    spot = spectrum.real**2 + spectrum.imag**2
    otf = scipy.fft.rfft2(spot.sum(axis=0))
    otf /= otf[:, :1, :1].real
    n_fft, half = plan.down.n_fft, plan.down.n_fft // 2
    out = np.zeros((otf.shape[0], n_fft, half), dtype=np.complex64)
    n_p = min(half, m // 2 + 1)
    rows = plan.q_index >= 0
    out[:, rows, :n_p] = otf[:, plan.q_index[rows], :n_p]
    return out


def exposure_images(wfs: ShackHartmann, downlink_phase_rad: np.ndarray,
                    phase_wavelength_m: float, elongation: np.ndarray | None = None,
                    uplink_phase_rad: np.ndarray | None = None) -> np.ndarray:
    """Images of one WFS exposure (mean over its time steps), physical optics.

    ``downlink_phase_rad`` (T, n_beacons, n, n) on ``wfs.grid``, cone effect
    applied; ``uplink_phase_rad`` (T, n_beacons, n_l, n_l) on
    ``wfs.launch_grid`` or None (point-like spot); both in rad at
    ``phase_wavelength_m``. ``elongation`` (n_valid, M, M//2+1) from
    :func:`lgs_elongation_otf` or None.

    The time-averaged downlink intensity is convolved (OTF product) with the
    elongation and with the exposure-averaged uplink spot (mean of the steps'
    uplink OTFs; exact when the uplink phase is constant over the exposure,
    otherwise it neglects the correlation between the 2.5 ms changes of the
    up- and down-link, a second-order effect), then pixel-integrated.
    Returns (n_beacons, n_valid, n_pixels, n_pixels) float32 in units of a
    full sub-aperture's flux over the exposure.

    Same result (to float32 rounding) as :func:`reference_exposure_images`,
    which chains :func:`intensity_samples`, :func:`intensity_spectra`,
    :func:`uplink_otf` and :func:`pixel_images`; here all steps, beacons and
    sub-apertures go through one fused, SIMD-vectorised kernel (see
    ``_lane_kernels``): pruned radix-2 FFTs of the fields, the steps'
    intensities summed before their single spectrum, the spot OTFs applied to
    the half-plane harmonics only; then the pixel integration is two complex
    matrix products for all sub-apertures at once.
    """
    downlink = np.ascontiguousarray(downlink_phase_rad, dtype=np.float32)
    if downlink.ndim != 4:
        raise ValueError("downlink phase must be (T, n_beacons, n, n)")
    n_steps, n_beacons = downlink.shape[:2]
    plan = _exposure_plan(wfs, n_beacons)
    down = plan.down
    n_fft, half = down.n_fft, down.n_fft // 2
    ratio = phase_wavelength_m / wfs.wavelength_m
    cos_p, sin_p = down.trig(downlink, ratio)
    if elongation is None:
        el = plan.no_elongation
    else:
        el = np.empty_like(plan.no_elongation)
        _gather_elongation(np.ascontiguousarray(elongation, dtype=np.complex64), plan.q_index,
                           min(half, wfs.fft_size // 2 + 1), el)
    spot = np.full((n_beacons, n_fft, half), 1.0 / (n_fft**2 * wfs.samples_per_subaperture**2
                                                     * n_steps), dtype=np.complex64)
    if uplink_phase_rad is not None:
        uplink = np.ascontiguousarray(uplink_phase_rad, dtype=np.float32)
        if uplink.ndim != 4:
            raise ValueError("uplink phase must be (T, n_beacons, n_l, n_l)")
        spot *= _exposure_uplink_otf(wfs, plan, uplink, ratio)
    # one spectrum per exposure (the steps' intensities summed) times the spot
    # OTFs (elongation x uplink x normalisation), then the pixel integrals
    lanes = down.lanes
    spectra = np.empty((n_fft, down.n_chunks * half * lanes), np.complex64)
    _lane_kernels(n_fft, down.n_in, lanes).spectra(cos_p, sin_p, down.amp.reshape(-1), n_steps,
                                                   down.n_chunks, el.reshape(-1),
                                                   spot.reshape(-1), spectra.reshape(-1))
    rows = (plan.ey @ spectra).reshape(wfs.n_pixels * down.n_chunks, half, lanes)
    pixels = np.matmul(plan.ex, rows).real  # (y, chunk, x, lane)
    pixels = pixels.reshape(wfs.n_pixels, down.n_chunks, wfs.n_pixels, lanes).transpose(1, 0, 2, 3)
    p = wfs.n_pixels
    images = pixels.reshape(n_beacons, -1, p, p, lanes).transpose(0, 1, 4, 2, 3)
    return np.ascontiguousarray(images.reshape(n_beacons, -1, p, p)[:, :wfs.n_valid])


def reference_exposure_images(wfs: ShackHartmann, downlink_phase_rad: np.ndarray,
                              phase_wavelength_m: float, elongation: np.ndarray | None = None,
                              uplink_phase_rad: np.ndarray | None = None) -> np.ndarray:
    """:func:`exposure_images` by the step-by-step public functions (slow, for tests)."""
    downlink = np.asarray(downlink_phase_rad)
    if downlink.ndim != 4:
        raise ValueError("downlink phase must be (T, n_beacons, n, n)")
    n_steps = downlink.shape[0]
    intensity = intensity_samples(wfs, downlink[0], phase_wavelength_m)
    for step in range(1, n_steps):  # T = 2 steps per exposure
        intensity_samples(wfs, downlink[step], phase_wavelength_m, out=intensity)
    spectra = intensity_spectra(wfs, intensity)
    spectra *= np.float32(1.0 / n_steps)
    if elongation is not None:
        spectra *= elongation
    if uplink_phase_rad is not None:
        uplink = uplink_otf(wfs, uplink_phase_rad, phase_wavelength_m).mean(axis=0)
        spectra *= uplink[:, None]
    return pixel_images(wfs, spectra)


def add_noise(images: np.ndarray, photons_per_subaperture: float, read_noise_e: float,
              rng: np.random.Generator) -> np.ndarray:
    """Photon (Poisson) and read (Gaussian, ``read_noise_e`` rms) noise, new array.

    ``images`` are in units of a full sub-aperture's flux over the exposure
    (see :func:`exposure_images`); ``photons_per_subaperture`` is the detected
    photon count of a full sub-aperture in one exposure.
    """
    expected = np.clip(images, 0, None) * photons_per_subaperture
    noisy = rng.poisson(expected).astype(np.float32)
    if read_noise_e > 0:
        noisy += rng.normal(0.0, read_noise_e, size=noisy.shape).astype(np.float32)
    return noisy / np.float32(photons_per_subaperture)


def centroids_rad(wfs: ShackHartmann, images: np.ndarray) -> np.ndarray:
    """Centre of gravity (n_beacons, 2, n_valid) [rad] of images (n_b, n_valid, p, p)."""
    x = wfs.pixel_centres_rad.astype(np.float32)
    flux = images.sum(axis=(-2, -1))
    flux = np.where(flux > 0, flux, np.inf)
    cx = np.einsum("...yx,x->...", images, x) / flux
    cy = np.einsum("...yx,y->...", images, x) / flux
    return np.stack([cx, cy], axis=-2)


def remove_tip_tilt(slopes_rad: np.ndarray) -> np.ndarray:
    """Remove each beacon's mean x and y slope (LGS tilt is unknown), new array."""
    return slopes_rad - slopes_rad.mean(axis=-1, keepdims=True)


def measure_slopes(wfs: ShackHartmann, downlink_phase_rad: np.ndarray,
                   phase_wavelength_m: float, elongation: np.ndarray | None = None,
                   uplink_phase_rad: np.ndarray | None = None,
                   photons_per_subaperture: float | None = None, read_noise_e: float = 0.0,
                   rng: np.random.Generator | None = None) -> np.ndarray:
    """Tilt-removed slopes (n_beacons, 2, n_valid) [rad] of one exposure.

    Chains :func:`exposure_images`, optional :func:`add_noise` (off unless
    ``photons_per_subaperture`` is given), :func:`centroids_rad` and
    :func:`remove_tip_tilt`.
    """
    images = exposure_images(wfs, downlink_phase_rad, phase_wavelength_m, elongation,
                             uplink_phase_rad)
    if photons_per_subaperture is not None:
        if rng is None:
            raise ValueError("noise needs an explicit rng")
        images = add_noise(images, photons_per_subaperture, read_noise_e, rng)
    return remove_tip_tilt(centroids_rad(wfs, images))
