"""
The published paper run, from its datasets
==========================================

Every figure of the study is drawn from a tidy xarray dataset, stored beside it as
``figures/<id>.nc``. The published paper-fidelity run keeps them in ``figures/paper/``
(250 s of telescope time per case, errors from 10 time blocks of 25 s), so its numbers can
be read, compared and re-plotted without running anything.
"""

from pathlib import Path

import matplotlib.pyplot as plt
import xarray as xr

import luckyao

# the checkout: this folder or the nearest above it with the published run
root = next(p for p in (Path.cwd(), *Path.cwd().parents) if (p / "figures" / "paper").is_dir())
paper = root / "figures" / "paper"

# %%
# Integrated-image Strehl against the fraction of frames kept
# -----------------------------------------------------------
# ``ltao.nc`` holds every case of the ``ltao`` figure: Strehl, FWHM and 50%-energy diameter
# of the integrated image per case, selection criterion and fraction, each with its
# Monte-Carlo error (``strehl_error``, ±1σ).
# (``luckyao.open_figure("ltao")`` opens ``figures/ltao.nc`` of a study you ran.)
ltao = xr.open_dataset(paper / "ltao.nc")
print(ltao.case.values)

fig, ax = plt.subplots(figsize=(6.4, 4.2), layout="constrained")
for case in ("ltao_r0_13.5cm", "ltao_wfs16", "ltao_wfs32", "noao_r0_13.5cm"):
    curve = ltao.sel(case=case, criterion="strehl")
    ax.errorbar(
        100 * curve.fraction,
        curve.strehl,
        yerr=curve.strehl_error,
        marker="o",
        ms=3,
        capsize=2,
        label=str(curve.label.values),
    )
ax.set_xscale("log")
ax.set_xlabel("frames kept [%]")
ax.set_ylabel("integrated-image Strehl at 800 nm")
ax.set_title("Selection by image Strehl, paper run")
ax.legend(fontsize="small")

# %%
# The long exposure and the best lucky image of every case
# --------------------------------------------------------
# ``longexp.nc`` is the table of the long-exposure Strehl with and without recentring;
# ``luckyao table`` prints it as Markdown, with the best lucky Strehl beside it.
longexp = xr.open_dataset(paper / "longexp.nc")
print(longexp)

# %%
# Redraw a figure
# ---------------
# ``luckyao.draw`` draws any figure's dataset again, as the workflow drew it: here the
# ``r0sweep`` figure, integrated-image quality against r0.
r0sweep = xr.open_dataset(paper / "r0sweep.nc")
luckyao.draw(r0sweep)
