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
* Sign convention as in :mod:`luckyao.optics.imaging`: a phase ``2 pi theta x / lambda``
  moves the spot by ``+theta``; slopes have the sign of the phase gradient.
* The images are all this module makes: their noise is :mod:`.detector`'s, the
  slope estimators are :mod:`.centroiders`' (the centre of gravity gives the mean
  angle of arrival [rad] = mean gradient of the optical path over the sub-aperture,
  Primot 2003 / Teague, when the spot is resolved by the pixels; with 0.84"
  pixels and a diffraction-limited spot it is quad-cell like, non-linear).

Arrays: phases ``(..., n, n)`` indexed ``[y, x]``; slopes ``(n_beacons, 2, n_valid)``
with axis 1 = (x, y) [rad]; images ``(n_beacons, n_valid, n_pixels, n_pixels)``.
"""

from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np
import scipy.fft

from ..optics.pupil import PupilGrid, Telescope
from ..units import ARCSEC_RAD
from .beacons import LgsConfig, altitude_limits_m, altitude_profile, elongation_offsets_rad
from .kernels import exposure_kernel, lane_otf, uplink_kernel
from .sampling import samples_per_subaperture


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
        """``n_s``: even number of pupil samples per sub-aperture side (:func:`.sampling.samples_per_subaperture`)."""
        return samples_per_subaperture(self.subaperture_m, self.n_pixels, self.pixel_scale_rad, self.wavelength_m)

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
    def sensed_mask(self) -> np.ndarray:
        """Pupil samples inside valid sub-apertures, bool (n, n): the only phases the WFS reads."""
        n_s = self.samples_per_subaperture
        return self.mask & np.kron(self.valid, np.ones((n_s, n_s), dtype=bool))

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
        return (np.fft.fftfreq(m) * m / self.period_rad, np.fft.rfftfreq(m) * m / self.period_rad)

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
                value = (np.exp(2j * np.pi * q * upper[:, None]) - np.exp(2j * np.pi * q * lower[:, None])) / (
                    2j * np.pi * q
                )
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
@numba.njit(cache=True, nogil=True)
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


@numba.njit(cache=True, nogil=True)
def _add_power(spectrum, out, overwrite):  # pragma: no cover (jit)
    """out (+)= |spectrum|^2 elementwise (float32)."""
    flat_s = spectrum.reshape(-1)
    flat_o = out.reshape(-1)
    for k in range(flat_s.size):
        z = flat_s[k]
        power = z.real * z.real + z.imag * z.imag
        flat_o[k] = power if overwrite else flat_o[k] + power


def intensity_samples(
    wfs: ShackHartmann, phase_rad: np.ndarray, phase_wavelength_m: float, out: np.ndarray | None = None
) -> np.ndarray:
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
    """Static elongation OTF (n_valid, M, M//2+1), read-only, for an LGS asterism.

    Altitudes are sampled finely enough that adjacent points are < 1/8 of an
    FFT sample apart on the sky (see :func:`luckyao.wfs.beacons.altitude_profile`).
    """
    z_low, z_high = altitude_limits_m(config)
    span = 1 / z_low - 1 / z_high
    baseline = np.hypot(*(wfs.subaperture_xy_m - config.launch_xy_m).T).max(initial=0.0)
    sample_rad = wfs.period_rad / wfs.fft_size
    n_z = int(np.clip(np.ceil(16 * baseline * span / sample_rad), 8, 2048))
    z_m, weights = altitude_profile(config, n_z)
    offsets = elongation_offsets_rad(wfs.subaperture_xy_m, config.launch_xy_m, config.height_m, z_m)
    otf = elongation_otf(wfs, offsets, weights)
    otf.flags.writeable = False  # static: exposure_images keeps its lane layout
    return otf


def uplink_otf(wfs: ShackHartmann, uplink_phase_rad: np.ndarray, phase_wavelength_m: float) -> np.ndarray:
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


def pixel_images(wfs: ShackHartmann, spectra: np.ndarray) -> np.ndarray:
    """Detector images (..., n_pixels, n_pixels) float32 [y, x] from spectra.

    Exact integration over the pixels of the band-limited intensity whose
    Fourier coefficients are ``spectra`` (..., M, M//2+1); values are
    fractions of a full sub-aperture's flux.
    """
    e_y, e_x = wfs._pixel_integrals
    return np.matmul(np.matmul(e_y, spectra), e_x.T).real.astype(np.float32)


# --- fused exposure (compiled in luckyao.wfs.kernels) ----------------------------------
# 48 sub-apertures per chunk (a multiple of 8): no padding for the 8x8 WFS (48 valid).
_LANES = 48


def _next_pow2(n: int) -> int:
    return 1 << max(1, int(n - 1).bit_length())


@dataclass(frozen=True, eq=False)
class _ExposurePlan:
    """Static layout of :func:`exposure_images` for one WFS, beacon count and
    number of uplink steps (0: point-like spot).

    Chunk ``b n_amp + a`` holds the sub-apertures ``lane_subaperture[a]`` (-1:
    padding) of beacon ``b``; ``n_lags`` bounds the harmonics (see
    :mod:`luckyao.wfs.kernels`).
    """

    exposure: object  # luckyao.wfs.kernels.exposure_kernel(...)
    uplink_otf: object  # luckyao.wfs.kernels.uplink_kernel(...)
    n_fft: int
    n_lags: int
    sources: np.ndarray  # (n_chunks, L) int32 offset of each lane's block in one step
    amp: np.ndarray  # (n_amp, n_s n_s L) float32 transmission [x, y, lane]
    lane_subaperture: np.ndarray  # (n_amp, L) int64
    q_index: np.ndarray  # (n_q,) int64 harmonic q = -(n_lags - 1) .. n_lags - 1, mod M
    point_line: np.ndarray  # (n_amp, 2, n_q, n_lags, L) float32 lane OTF 1 (no elongation)
    ey: np.ndarray  # (n_pix, n_q) complex64 pixel integrals E_y
    ex: np.ndarray  # (n_pix, n_lags) complex64 weighted E_x
    point_spot: np.ndarray  # (n_beacons, n_q, n_lags) complex64 ones (no uplink)
    launch_amp: np.ndarray  # (n_l n_l lanes,) float32 launch mask [x, y, (t, beacon)]
    elongation_cache: dict  # "otf": (last read-only elongation OTF, its lane layout)


def _exposure_plan(wfs: ShackHartmann, n_beacons: int, uplink_steps: int) -> _ExposurePlan:
    plans = wfs.__dict__.setdefault("_exposure_plans", {})
    if (n_beacons, uplink_steps) in plans:
        return plans[n_beacons, uplink_steps]
    lanes, n_s, n_v, n = _LANES, wfs.samples_per_subaperture, wfs.n_valid, wfs.grid.n_pix
    n_amp = -(-n_v // lanes)
    v = np.arange(n_amp * lanes)
    index = wfs.subaperture_index[np.minimum(v, n_v - 1)]
    offset = (index[:, 0] * n_s * n + index[:, 1] * n_s).reshape(n_amp, lanes)
    sources = (np.arange(n_beacons)[:, None, None] * n * n + offset).reshape(-1, lanes)
    amp = np.zeros((n_amp * lanes, n_s, n_s), dtype=np.float32)
    amp[:n_v] = wfs.amplitude
    amp = amp.reshape(n_amp, lanes, n_s, n_s).transpose(0, 3, 2, 1).reshape(n_amp, -1)
    n_launch = wfs.launch_grid.n_pix
    n_lags = min(n_s, n_launch) if uplink_steps else n_s
    q = np.arange(1 - n_lags, n_lags)
    e_y, e_x = wfs._pixel_integrals
    ey, ex = e_y[:, q % wfs.fft_size], e_x[:, :n_lags]
    n_fft = _next_pow2(2 * n_s)
    n_fields = uplink_steps * n_beacons
    launch_amp = np.zeros((n_launch, n_launch, max(16, -(-n_fields // 8) * 8)), dtype=np.float32)
    launch_amp[:, :, :n_fields] = wfs.launch_mask.T[:, :, None]
    point_line = np.zeros((n_amp, 2, q.size, n_lags, lanes), dtype=np.float32)
    point_line[:, 0] = 1.0
    plan = _ExposurePlan(
        exposure_kernel(n_fft, n_s, lanes, n_lags, wfs.n_pixels),
        uplink_kernel(_next_pow2(2 * n_launch), n_launch, uplink_steps, n_beacons, n_lags) if uplink_steps else None,
        n_fft,
        n_lags,
        sources.astype(np.int32),
        np.ascontiguousarray(amp),
        np.where(v < n_v, v, -1).reshape(n_amp, lanes),
        q % wfs.fft_size,
        point_line,
        np.ascontiguousarray(ey),
        np.ascontiguousarray(ex),
        np.ones((n_beacons, q.size, n_lags), dtype=np.complex64),
        launch_amp.reshape(-1),
        {},
    )
    plans[n_beacons, uplink_steps] = plan
    return plan


def _lane_elongation(plan: _ExposurePlan, elongation: np.ndarray) -> np.ndarray:
    """``elongation`` in the lane layout of ``plan`` (see ``kernels.lane_otf``); kept
    for the next call when read-only (as from :func:`lgs_elongation_otf`)."""
    cached = plan.elongation_cache.get("otf")
    if cached is not None and cached[0] is elongation:
        return cached[1]
    lanes = np.empty_like(plan.point_line)
    lane_otf(np.asarray(elongation, dtype=np.complex64), plan.q_index, plan.n_lags, plan.lane_subaperture, lanes)
    if not elongation.flags.writeable:
        plan.elongation_cache["otf"] = (elongation, lanes)
    return lanes


def exposure_images(
    wfs: ShackHartmann,
    downlink_phase_rad: np.ndarray,
    phase_wavelength_m: float,
    elongation: np.ndarray | None = None,
    uplink_phase_rad: np.ndarray | None = None,
) -> np.ndarray:
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

    Same result (to float32 rounding) as chaining :func:`intensity_samples`,
    :func:`intensity_spectra`, :func:`uplink_otf` and :func:`pixel_images` (the tests'
    reference); here compiled kernels
    (:mod:`luckyao.wfs.kernels`) get the exposure spectra as field
    autocorrelations, only on the harmonics where the spot OTFs are non-zero.
    """
    downlink = np.ascontiguousarray(downlink_phase_rad, dtype=np.float32)
    if downlink.ndim != 4 or downlink.shape[2:] != (wfs.grid.n_pix,) * 2:
        raise ValueError("downlink phase must be (T, n_beacons, n, n)")
    n_steps, n_beacons = downlink.shape[:2]
    uplink = None if uplink_phase_rad is None else np.ascontiguousarray(uplink_phase_rad, dtype=np.float32)
    plan = _exposure_plan(wfs, n_beacons, 0 if uplink is None else uplink.shape[0])
    ratio = np.float32(phase_wavelength_m / wfs.wavelength_m)
    if uplink is None:
        spot = plan.point_spot
    else:
        n_launch = wfs.launch_grid.n_pix
        if uplink.shape[1:] != (n_beacons, n_launch, n_launch):
            raise ValueError("uplink phase must be (T, n_beacons, n_l, n_l)")
        spot = np.empty_like(plan.point_spot)
        plan.uplink_otf(uplink.reshape(-1), ratio, plan.launch_amp, spot)
    el = plan.point_line if elongation is None else _lane_elongation(plan, elongation)
    norm = np.float32(1.0 / (plan.n_fft * wfs.samples_per_subaperture**2 * n_steps))
    images = np.empty((n_beacons, wfs.n_valid, wfs.n_pixels, wfs.n_pixels), dtype=np.float32)
    plan.exposure(
        downlink.reshape(-1),
        n_steps,
        wfs.grid.n_pix,
        ratio,
        norm,
        plan.sources,
        plan.amp,
        plan.lane_subaperture,
        el,
        spot,
        plan.ey,
        plan.ex,
        images,
    )
    return images
