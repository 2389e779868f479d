"""Frozen-flow phase screens: one long strip per layer along its wind.

Stored screens are normalised: phase in rad at 500 nm for a layer of r0 = 1 m,
so a layer of Cn2 fraction ``f`` in an atmosphere of Fried parameter ``r0``
contributes ``r0 ** (-5/6) * sqrt(f) * screen`` (phase variance scales as
``r0 ** (-5/3)``, Fried 1966).

Each layer's screen is a long strip along its wind, sampled on the sky grid
(see ``StripSpec``); frozen flow moves it by ``v dt / dx_m`` samples per time
step (any real number: the propagator interpolates).
"""

from dataclasses import dataclass

import numpy as np
import scipy.fft

from .statistics import Layer, von_karman_psd


@dataclass(frozen=True)
class StripSpec:
    """Sampling of one layer's strip screen: a skewed strip of sky-aligned samples.

    Samples lie on a sky grid of spacing ``dx_m``. The strip runs along the
    wind; its major axis is sky x (``major_axis = 0``) or y (1), whichever is
    closer to the wind. Sample ``[i, j]`` of the (n_major, n_minor) array sits
    at (major, minor) = ``origin_m + dx_m (i, j + line_offset(i))``: each major
    line is moved by a whole number of samples, ``floor(skew i / n_major)``, so
    the strip follows the wind while every footprint of a pupil grid stays an
    axis-aligned grid on it (one bilinear interpolation, separable weights).
    Frozen flow moves the screen by ``step_samples`` (major, minor) per time step.
    """

    dx_m: float
    n_major: int
    n_minor: int
    major_axis: int
    skew: int
    origin_m: tuple[float, float]
    step_samples: tuple[float, float]

    def line_offset(self, i):
        """Minor offset [samples] of major line(s) ``i``."""
        return (self.skew * np.asarray(i, dtype=np.int64)) // self.n_major


def strip_spec(
    layer: Layer,
    time_step_s: float,
    n_steps: int,
    dx_m: float,
    radius_m: float,
    min_along_m: float,
    min_across_m: float,
) -> StripSpec:
    """Strip that holds every footprint within ``radius_m`` of the axis for ``n_steps``.

    The screen moves by ``v dt`` per step, so a point fixed on the sky samples
    screen position ``x - v t``: footprints slide along ``-v``. A disk of
    radius ``R`` sliding at angle ``a`` to the major axis spans ``+-R / cos a``
    across a major line. The strip's along-wind period is at least
    ``min_along_m`` and its width across the wind at least ``min_across_m``
    (large scales, see ``strip_screen``).
    """
    e = layer.wind_unit
    major = 0 if abs(e[0]) >= abs(e[1]) else 1
    e_major, e_minor = e[major], e[1 - major]
    slope, cos = e_minor / e_major, abs(e_major)
    travel_m = layer.wind_speed_m_s * time_step_s * n_steps
    reach_m = radius_m + 2 * dx_m
    n_major = scipy.fft.next_fast_len(
        int(np.ceil(max((abs(e_major) * travel_m + 2 * reach_m) / dx_m + 2, min_along_m * cos / dx_m)))
    )
    n_minor = scipy.fft.next_fast_len(int(np.ceil(max(2 * reach_m / (cos * dx_m) + 6, min_across_m / (cos * dx_m)))))
    origin_major = min(0.0, -e_major * travel_m) - reach_m
    # the band's centre line, minor = slope * major, falls near the middle sample of every line
    origin_minor = slope * origin_major - (n_minor - 1) * dx_m / 2
    step_m = layer.wind_speed_m_s * time_step_s
    return StripSpec(
        dx_m=dx_m,
        n_major=n_major,
        n_minor=n_minor,
        major_axis=major,
        skew=int(round(n_major * slope)),
        origin_m=(origin_major, origin_minor),
        step_samples=(step_m * e_major / dx_m, step_m * e_minor / dx_m),
    )


def _across_rows(dfy: float, refined: int, split: int, subharmonic_levels: int):
    """Minor-axis frequencies [1/m] and widths of the finely sampled rows near f_y = 0."""
    rows = []
    for m in [*range(-refined, 0), *range(1, refined + 1)]:
        rows += [((m - 0.5 + (s + 0.5) / split) * dfy, dfy / split) for s in range(split)]
    for level in range(1, subharmonic_levels + 1):
        width = dfy / 3**level
        rows += [(-width, width), (width, width)]
    rows.append((0.0, dfy / 3**subharmonic_levels))
    return np.array(rows).T


def strip_screen(
    spec: StripSpec,
    outer_scale_m: float,
    rng: np.random.Generator,
    refined_rows: int = 2,
    row_split: int = 3,
    subharmonic_levels: int = 3,
) -> np.ndarray:
    """Von Karman phase strip [rad at 500 nm for r0 = 1 m], float32 (n_major, n_minor).

    FFT method (McGlamery 1976), ``Re sum_f c_f sqrt(Phi(f) df) exp(2 pi i f.r)``
    with complex unit normal ``c_f``, on the skewed lattice of the strip: it
    is periodic along ``(N, K)`` samples (the wind) and ``(0, M)``, whose dual
    frequencies are ``f = ((p - K f_y dx) / (N dx), f_y)``, ``f_y = q / (M dx)``.
    With ``r = dx (i, j + floor(K i / N))`` the sum is a 1-D FFT over ``p``, a
    twiddle ``exp(-2 pi i f_y dx frac(K i / N))`` and a 1-D FFT over ``q``.
    The strip is long (many L0) along the wind, so its along-wind cells are
    fine. Across it, the rows ``|q| <= refined_rows`` are resampled
    ``row_split`` times finer and the cell around ``f_y = 0`` is split into
    thirds ``subharmonic_levels`` times (Lane et al. 1992; Johansson & Gavel
    1994); each such row is one FFT over ``p``. With the defaults and a strip
    >= 4 D wide, the expected structure function is within 1 % of von Karman
    for D = 4.2 m, L0 = 20 m at separations of 5 samples to D (2.7 % low at 2
    samples: no power beyond the sampling frequency).
    """
    n, m, dx, k = spec.n_major, spec.n_minor, spec.dx_m, spec.skew
    p = np.arange(n)
    offset = (k * p % n) / n  # frac(K i / N), i = p
    q = np.round(np.fft.fftfreq(m) * m)  # signed minor frequency index
    dfx, dfy = 1 / (n * dx), 1 / (m * dx)
    columns, lines = max(1, 2**22 // n), max(1, 2**22 // m)  # blocks that bound the temporaries

    def major_frequency(f_minor):
        """Major-axis frequency [1/m] of index p on the row of minor frequency f_minor (alias nearest 0)."""
        z = p[:, None] - k * dx * np.asarray(f_minor)[None, :]
        return (z - n * np.round(z / n)) * dfx

    def coefficients(f_minor, cell_area):
        f2 = major_frequency(f_minor) ** 2 + np.asarray(f_minor)[None, :] ** 2
        amplitude = np.sqrt(von_karman_psd(np.sqrt(f2), 1.0, outer_scale_m) * cell_area).astype(np.float32)
        normal = rng.standard_normal((2,) + f2.shape, dtype=np.float32)
        return amplitude * (normal[0] + np.complex64(1j) * normal[1])

    def twiddle(block, f_minor):
        return np.exp(-2j * np.pi * dx * offset[block, None] * np.asarray(f_minor)[None, :]).astype(np.complex64)

    coarse = np.abs(q) <= refined_rows  # replaced by the finer rows below
    spectrum = np.empty((n, m), dtype=np.complex64)
    for start in range(0, m, columns):
        cols = slice(start, start + columns)
        spectrum[:, cols] = coefficients(q[cols] * dfy, dfx * dfy)
    spectrum[:, coarse] = 0
    spectrum = scipy.fft.ifft(spectrum, axis=0, norm="forward", workers=-1, overwrite_x=True)
    screen = np.empty((n, m), dtype=np.float32)
    for start in range(0, n, lines):
        block = slice(start, start + lines)
        shifted = spectrum[block] * twiddle(block, q * dfy)
        screen[block] = scipy.fft.ifft(shifted, axis=1, norm="forward", workers=-1, overwrite_x=True).real
    del spectrum
    row_f, row_width = _across_rows(dfy, refined_rows, row_split, subharmonic_levels)
    rows = coefficients(row_f, dfx * row_width[None, :])
    rows[0, -1] = 0  # piston
    along = scipy.fft.ifft(rows, axis=0, norm="forward", workers=-1)
    across = np.exp(2j * np.pi * row_f[:, None] * (np.arange(m) * dx)[None, :]).astype(np.complex64)
    for start in range(0, n, lines):
        block = slice(start, start + lines)
        screen[block] += ((along[block] * twiddle(block, row_f)) @ across).real
    return screen


def periodic_screen_amplitude(psd, n: int, dx_m: float) -> np.ndarray:
    """``sqrt(Phi(f) df^2)`` (n, n) on the FFT frequencies of an (n, n) grid of spacing
    ``dx_m``, no piston: the amplitudes of :func:`periodic_screen_pair` for the power
    spectrum ``psd(f)`` [rad^2 m^2] (a callable of the frequency [1/m])."""
    f = np.fft.fftfreq(n, dx_m)
    amplitude = np.sqrt(psd(np.hypot(f[:, None], f[None, :]))) / (n * dx_m)
    amplitude[0, 0] = 0.0
    return amplitude


def periodic_screen_pair(amplitude: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Two independent periodic phase screens (n, n) float64: the real and imaginary parts
    of ``sum_f c_f sqrt(Phi(f) df^2) exp(2 pi i f.r)``, ``c_f`` complex unit normal
    (McGlamery 1976), ``amplitude`` from :func:`periodic_screen_amplitude`. No
    subharmonics: scales beyond the screen are missing, so use them on a pupil several
    times smaller (draws of sub-aperture-scale statistics, not the time series)."""
    normal = rng.standard_normal((2,) + amplitude.shape)
    screen = scipy.fft.ifft2(amplitude * (normal[0] + 1j * normal[1]), norm="forward")
    return screen.real, screen.imag


@dataclass(frozen=True, eq=False)
class ScreenSet:
    """Every layer's strip, flattened into one float32 buffer (possibly memory-mapped).

    Layer ``l`` occupies ``flat[starts[l] : starts[l] + n_major * n_minor]`` in
    row-major (major, minor) order.
    """

    specs: tuple[StripSpec, ...]
    flat: np.ndarray
    starts: np.ndarray

    @classmethod
    def from_screens(cls, specs, screens) -> "ScreenSet":
        sizes = [s.n_major * s.n_minor for s in specs]
        flat = np.concatenate([np.asarray(s, dtype=np.float32).ravel() for s in screens])
        return cls(tuple(specs), flat, np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64))

    def screen(self, layer: int) -> np.ndarray:
        s = self.specs[layer]
        start = self.starts[layer]
        return self.flat[start : start + s.n_major * s.n_minor].reshape(s.n_major, s.n_minor)
