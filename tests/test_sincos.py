"""Float32 sine and cosine against numpy's float64 values."""

import numpy as np

from luckyao.optics.sincos import cos_sin


def test_float32_sincos_is_accurate_to_one_ulp():
    x = np.concatenate([np.linspace(-10, 10, 20001), np.random.default_rng(0).uniform(-6000, 6000, 20000)]).astype(
        np.float32
    )
    cos_x, sin_x = np.empty_like(x), np.empty_like(x)
    cos_sin(x, cos_x, sin_x)
    np.testing.assert_allclose(cos_x, np.cos(x.astype(float)), rtol=0, atol=1e-7)
    np.testing.assert_allclose(sin_x, np.sin(x.astype(float)), rtol=0, atol=1e-7)
