"""
luckyao from Python
===================

Run a case without Snakemake, read its results, write its images as FITS, and open a
finished study's figures::

    .venv/bin/python docs/examples/tutorial.py [OUT_DIR]     # from the repository root; about a minute

Each step is a few lines to copy into a notebook. ``tests/test_api.py`` runs this script, and
the documentation's gallery runs it at every build, so it keeps working.
"""

import sys
from pathlib import Path

import luckyao

out = Path(sys.argv[1] if len(sys.argv) > 1 else "tutorial-output")
out.mkdir(parents=True, exist_ok=True)
# the checkout: this folder or the nearest above it that holds the study's config (so this
# runs from the repository root, from docs/examples, or in a notebook anywhere inside)
root = next(p for p in (Path.cwd(), *Path.cwd().parents) if (p / "config" / "config.yaml").exists())

# %%
# 1. A study config
# -----------------
# The default study's (every key is described in the documentation's configuration
# reference). For a quick look, half a second of telescope time (50 lucky frames of 10 ms)
# and screens made for just that.
study = luckyao.load_study(root / "config" / "config.yaml")
study["turbulence"].update(duration_s=0.5, min_along_m=30.0)
study["base"]["duration_s"] = 0.5

# %%
# 2. Run one case
# ---------------
# Any override of the study's base, here LTAO under poor seeing (r0 = 10 cm). The
# workflow's own steps run as the workflow runs them, without Snakemake: screens, WFS
# calibration, tomographic reconstructor, AO command matrix, time loop, lucky imaging (the
# same config and seed give the workflow's numbers).
lucky = luckyao.run_case(
    study, {"ao": {"mode": "ltao"}, "atmosphere": {"r0_500nm_m": 0.10}}, name="ltao_r0_10cm", workdir=out / "run"
)

# %%
# 3. Its results
# --------------
# An xarray Dataset: Strehl, FWHM and 50%-energy diameter of the integrated image per
# registration method (here ``cog`` alone: the whole frame's centre of gravity), selection
# criterion, fraction of frames and detector, each with its Monte-Carlo error from time
# blocks.
best = lucky.strehl.sel(registration="cog", detector="noiseless", criterion="lgs_rms").isel(target=0)
error = lucky.strehl_error.sel(registration="cog", detector="noiseless", criterion="lgs_rms").isel(target=0)
for fraction in best.fraction.values:
    print(
        f"selection by lgs_rms, {100 * fraction:5.1f} % of frames: Strehl "
        f"{float(best.sel(fraction=fraction)):.4f} ± {float(error.sel(fraction=fraction)):.4f}"
    )
long_exposure = lucky.long_exposure_strehl.sel(registration="cog", detector="noiseless", recentring="none")
print(f"long exposure (all frames, no recentring): Strehl {float(long_exposure.isel(target=0)):.4f}")

# %%
# 4. The images as FITS
# ---------------------
# For DS9, astropy or any PSF tool: one extension per image (found by name or through the
# INDEX table, extension 1), with the pixel scale (WCS), wavelength, exposure time,
# Strehl/FWHM/d50 and errors, registration method, seed and config hash.
fits_path = out / "ltao_r0_10cm.fits"
n_images = luckyao.export_fits(out / "run" / "ltao_r0_10cm" / "lucky.nc", fits_path)
from astropy.io import fits  # noqa: E402

with fits.open(fits_path) as hdus:
    header = hdus["LUCKY_T0_COG_LGS_RMS_0.01_NOISELESS"].header
    print(
        f"{fits_path}: {n_images} images; 1 % by lgs_rms: Strehl {header['STREHL']:.4f} ± {header['STREHLE']:.4f}, "
        f"{header['CDELT1']:.4f} arcsec/pixel, {header['WAVELENG'] * 1e9:.0f} nm"
    )

# %%
# 5. A finished study
# -------------------
# After ``bash run.sh study``: open any case and any figure's tidy data, and draw the figure
# again, e.g. to restyle it (skipped where no study was run).
if (root / "figures" / "r0sweep.nc").exists():
    data = luckyao.open_figure("r0sweep", study_dir=root)
    print(data.strehl.sel(criterion="lgs_rms", fraction=0.01).to_pandas())
    luckyao.draw(data).savefig(out / "r0sweep.png", dpi=100)
    case = luckyao.open_case("ltao_r0_13.5cm", study_dir=root)
    print(case.strehl.sel(registration="cog", detector="noiseless", fraction=0.01).isel(target=0).to_pandas())
