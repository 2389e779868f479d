"""FITS cards of a noise-dominated image: its NaN metrics are FITS's undefined value."""

import numpy as np
from astropy.io import fits

from luckyao.io.fits import _hdu


def test_a_nan_metric_is_written_as_an_undefined_card_and_reads_back(tmp_path):
    """FITS has no NaN: a noise-dominated image's Strehl (NaN) becomes an undefined card,
    said so in its comment; finite cards and the pixels are unchanged (before, astropy
    refused the whole file)."""
    image = np.full((4, 4), 1 / 32, dtype=np.float32)
    hdu = _hdu(fits, image, "LUCKY", [("STREHL", float("nan"), "Strehl ratio"), ("D50", 0.41, "[arcsec] d50")])
    path = tmp_path / "x.fits"
    fits.HDUList([fits.PrimaryHDU(), hdu]).writeto(path)
    with fits.open(path) as hdus:
        header = hdus["LUCKY"].header
        assert header["STREHL"] is None  # astropy reads an undefined value as None
        assert "undefined" in header.comments["STREHL"]
        assert header["D50"] == 0.41 and header["FLUXFRAC"] == 0.5
        np.testing.assert_array_equal(hdus["LUCKY"].data, image)
