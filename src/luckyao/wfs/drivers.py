"""Per-size drivers of the compiled Shack-Hartmann exposure, as templates.

These are plain Python functions, never called as they stand: their free names (the
sizes and the generated codelets ``columns``, ``correlate``, ``spectrum``, ``pixels``)
are bound by :func:`luckyao.wfs.kernels.exposure_kernel` and
:func:`luckyao.wfs.kernels.uplink_kernel`, which write each template's source below
those bindings into a generated module of one size. Numba then caches the compiled
driver on disk like any module-level function (a closure over the codelets could not
be cached: every process would spend seconds of LLVM optimisation on it).
"""
# ruff: noqa: F821  (the free names are bound in the generated module)


def exposure(
    phase, n_steps, row_m, ratio, norm, sources, amp, lane_subaperture, elongation, spot, ey, ex, images
):  # pragma: no cover (jit)
    """images[b, v, j, k] of one exposure.

    ``phase`` flat (T, n_b, n, n) [rad at the phase wavelength, x ``ratio``
    at the WFS wavelength]; chunk ``b n_amp + a`` holds beacon ``b``'s
    sub-apertures ``lane_subaperture[a]`` (-1: padding), whose offsets in
    one step's phase are ``sources[chunk]`` and transmissions ``amp[a]``
    (x, y, lane); ``elongation[a]`` their elongation OTFs (``lane_otf``);
    ``spot`` (n_b, n_q, n_lags) uplink OTF; ``norm`` the spectrum normalisation;
    pixel integrals ``ey`` (n_pix, n_q) and ``ex`` (n_pix, n_lags).
    """
    n_b = images.shape[0]
    w = np.empty(n_b * size_w, np.float32)
    pixel_weights(spot, ey, ex, norm, w)
    phi = np.empty(n_in * n_in * lanes, np.float32)
    g = np.empty(2 * n_fft * n_in * lanes, np.float32)
    h = np.empty(2 * n_fft * n_lags * lanes, np.float32)
    c = np.empty(2 * n_q * n_lags * lanes, np.float32)
    pix = np.empty(n_pix * n_pix * lanes, np.float32)
    step = phase.size // n_steps
    n_amp = amp.shape[0]
    for a in range(n_amp):
        el = elongation[a].reshape(-1)
        for b in range(n_b):
            chunk = b * n_amp + a
            for t in range(n_steps):
                gather(phase[t * step : (t + 1) * step], sources[chunk], row_m, n_in, phi)
                columns(phi, ratio, amp[a], g)
                correlate(g, h, t > 0)
            spectrum(h, c)
            pixels(c, el, w[b * size_w : (b + 1) * size_w], pix)
            for lane in range(lanes):
                v = lane_subaperture[a, lane]
                if v >= 0:
                    for j in range(n_pix):
                        for k in range(n_pix):
                            images[b, v, j, k] = pix[(j * n_pix + k) * lanes + lane]


def uplink_otf(phase, ratio, mask, otf):  # pragma: no cover (jit)
    """otf[b, q + n_lags - 1, p] = U_b[q, p] / U_b[0, 0]: ``U_b`` the exposure
    spectrum of beacon b's launch fields ``mask exp(i ratio phase)``, ``phase``
    flat (T, n_b, n_l, n_l), ``mask`` (x, y, lane) float32, 0 on padding lanes."""
    phi = np.empty(mask.size, np.float32)
    g = np.empty(2 * n_fft * n_launch * lanes, np.float32)
    h = np.empty(2 * n_fft * n_lags * lanes, np.float32)
    c = np.empty(2 * n_q * n_lags * lanes, np.float32)
    gather(phase, sources, n_launch, n_launch, phi)
    columns(phi, ratio, mask, g)
    correlate(g, h, False)
    spectrum(h, c)
    im = c.size // 2
    for b in range(n_beacons):
        flux = 0.0
        for t in range(n_steps):
            flux += c[(n_lags - 1) * n_lags * lanes + t * n_beacons + b]
        for q in range(n_q):
            for p in range(n_lags):
                z = 0j
                for t in range(n_steps):
                    i = (q * n_lags + p) * lanes + t * n_beacons + b
                    z += complex(c[i], c[im + i])
                otf[b, q, p] = z / flux
