"""Integrated-image quality figures: vs the fraction of frames selected, vs the target's
off-axis distance, vs a swept parameter, and paired differences between cases."""

import numpy as np
import xarray as xr

from ..lucky.accumulation import batch_mean_error, block_error
from ..lucky.dataset import NOISE_DOMINATED, noise_flag_attrs
from ..lucky.dataset import noise_dominated as noise_dominated_values
from ..studyspec.schema import key_units
from .settings import FigureSettings, case_coords
from .style import (
    AO_STYLE,
    CRITERIA,
    LINE_STYLES,
    MARKERS,
    METRICS,
    band,
    colour,
    fraction_axis,
    limit_flags,
    new_figure,
    parameter,
    series_fraction_lines,
    unflagged,
    with_error,
)


def noise_dominated(ds: xr.Dataset, metric: str) -> xr.DataArray:
    """Where ``metric`` of a lucky dataset (or a selection of it) is noise-dominated
    (:func:`luckyao.lucky.dataset.noise_dominated`); False where the dataset has no noiseless counterpart."""
    if f"{metric}_noiseless" not in ds:
        return xr.zeros_like(ds[metric], dtype=bool)
    return noise_dominated_values(ds[metric], ds[f"{metric}_noiseless"])


def _noise_flags(data: dict, dims, rows) -> None:
    """Add ``<metric>_noise_dominated`` (int8) to ``data`` from per-case selections ``rows``."""
    for metric in METRICS:
        flags = np.array([noise_dominated(row, metric).values for row in rows], dtype=np.int8)
        data[f"{metric}_noise_dominated"] = (dims, flags, noise_flag_attrs(metric))


def _drawn(values: xr.Dataset, metric: str) -> np.ndarray:
    """A curve's values with its flagged points left out (NaN): noise-dominated, beyond the
    diffraction limit, a d50 set by the field (:func:`.style.unflagged`)."""
    return unflagged(values, metric)


def quality_vs_fraction_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Integrated-image quality (first target) vs fraction selected, per case and criterion."""
    detector, criteria = settings.detector, list(settings.criteria)
    data_vars = {}
    rows = [ds.sel(criterion=criteria, detector=detector).isel(target=0) for ds in datasets]
    for metric in METRICS:
        for name in with_error(datasets, metric) + limit_flags(datasets, metric):
            data_vars[name] = (
                ("case", "criterion", "fraction"),
                np.array([row[name].values for row in rows]),
                dict(datasets[0][name].attrs),
            )
    _noise_flags(data_vars, ("case", "criterion", "fraction"), rows)
    long_exposure = [ds["long_exposure_strehl"].sel(detector=detector).isel(target=0).values for ds in datasets]
    data_vars["long_exposure_strehl"] = (
        ("case", "recentring"),
        np.array(long_exposure),
        dict(datasets[0]["long_exposure_strehl"].attrs),
    )
    ds = xr.Dataset(
        data_vars,
        coords={
            **case_coords(settings, datasets),
            "criterion": ("criterion", criteria, {"long_name": "selection criterion"}),
            "fraction": datasets[0]["fraction"],
            "recentring": datasets[0]["recentring"],
        },
    )
    ds.attrs.update(detector=detector)
    return ds


def _case_style(ds: xr.Dataset, case) -> dict:
    """A case's colour and marker by its place in the figure, its line style by its AO mode."""
    row = ds.sel(case=case)
    k = int(row.colour)
    return {"color": colour(k), "marker": MARKERS[k % len(MARKERS)], "ls": AO_STYLE[str(row.ao_mode.values)]}


def _legend_note(ds: xr.Dataset) -> str:
    """What the drawing left out, by flag (none set: nothing said)."""

    def flagged(suffix: str) -> bool:
        return any(int(ds[v].sum()) for v in ds.data_vars if v.endswith(suffix))

    notes = [
        (
            "_noise_dominated",
            f"noise-dominated points (more than {NOISE_DOMINATED:.0%} off the same selection on the noiseless "
            "frames) left out",
        ),
        (
            "_beyond_diffraction_limit",
            "points beyond the diffraction limit (Strehl above 1, FWHM or d50 below) left out",
        ),
        ("_field_bound", "d50 set by the field (a lower bound) left out"),
    ]
    return "".join(f"\n{note}" for suffix, note in notes if flagged(suffix))


COINCIDE_RTOL = 1e-5
"""Curves whose every value agrees to this relative difference (far below a pixel) coincide:
drawn once, the legend naming them all."""


def coinciding_cases(ds: xr.Dataset) -> list[list]:
    """The cases of a figure's dataset (one panel row's selection) in groups whose curves
    coincide (:data:`COINCIDE_RTOL`, every data variable), in the figure's order."""
    groups: list[list] = []
    for case in ds.case.values:
        row = ds.sel(case=case)
        for group in groups:
            first = ds.sel(case=group[0])
            if all(
                np.allclose(row[v].values, first[v].values, rtol=COINCIDE_RTOL, atol=0.0, equal_nan=True)
                for v in ds.data_vars
            ):
                group.append(case)
                break
        else:
            groups.append([case])
    return groups


def coinciding_label(labels: list[str]) -> str:
    """One legend label for coinciding curves: what their labels share, then what differs,
    ``no AO, 8x8 WFS = 16x16 WFS = 32x32 WFS (identical)``."""
    if len(labels) == 1:
        return labels[0]
    parts = [label.split(", ") for label in labels]
    shared = [p for p in parts[0] if all(p in other for other in parts)]
    differ = [", ".join(p for p in part if p not in shared) or "all" for part in parts]
    return ", ".join(shared + [" = ".join(differ)]) + " (identical)"


def draw_quality_vs_fraction(ds: xr.Dataset, title: str):
    n_rows = ds.sizes["criterion"]
    fig = new_figure(13, 3.6 * n_rows + 0.9)
    axes = fig.subplots(n_rows, 3, squeeze=False)
    x = 100 * ds.fraction.values
    merged = False
    for r, criterion in enumerate(ds.criterion.values):
        panel = ds.sel(criterion=criterion)
        groups = coinciding_cases(panel)
        merged |= any(len(group) > 1 for group in groups)
        for ax, metric in zip(axes[r], METRICS):
            for group in groups:
                row, style = panel.sel(case=group[0]), _case_style(ds, group[0])
                label = coinciding_label([str(panel.label.sel(case=c).values) for c in group])
                ax.plot(x, _drawn(row, metric), ms=3.5, label=label, **style)
                band(ax, x, row, metric, style["color"])
                if metric == "strehl":
                    ax.axhline(
                        float(row.long_exposure_strehl.sel(recentring="none")), lw=0.8, color=style["color"], ls=":"
                    )
            fraction_axis(ax)
            ax.set_ylabel(METRICS[metric])
            ax.grid(alpha=0.3)
        letter = f"({chr(ord('a') + r)}) " if n_rows > 1 else ""
        axes[r, 0].set_title(f"{letter}selection by {CRITERIA.get(criterion, criterion)}", loc="left", fontsize=10)
    handles = {}
    for ax in axes[:, 0]:  # every row's curves, a coinciding group said once
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    fig.legend(
        handles.values(),
        handles.keys(),
        loc="outside lower center",
        ncol=4,
        fontsize=8,
        title="colour and marker: case; line style: AO (solid LTAO, dash-dot GLAO, dashed none); dotted: long "
        "exposure (no recentring)\nbands: ±1 Monte-Carlo standard error"
        + ("; identical: curves that coincide in a row, drawn once" if merged else "")
        + _legend_note(ds),
        title_fontsize=8,
    )
    fig.suptitle(f"{title}: integrated-image quality vs fraction selected ({ds.attrs['detector']} detector)")
    return fig


def quality_vs_distance_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Integrated-image quality vs the target's off-axis distance, per case, criterion and
    fraction (field cases: the image criteria and the recentring from the case's reference
    star, ``lgs_rms`` along each target), with each target's mean true residual rms and its
    long-exposure Strehl (no recentring)."""
    detector, criteria, fractions = settings.detector, list(settings.criteria), list(settings.fractions)
    first = datasets[0]
    distance = np.hypot(first.target_x_arcsec.values, first.target_y_arcsec.values)
    for name, ds in zip(settings.cases, datasets):
        other = np.hypot(ds.target_x_arcsec.values, ds.target_y_arcsec.values)
        if other.shape != distance.shape or not np.allclose(other, distance):
            raise ValueError(f"case {name}: targets at {other} arcsec, the first case's at {distance}")
    sel = ("case", "criterion", "fraction", "distance")
    data = {
        name: (
            sel,
            np.array(
                [
                    ds[name]
                    .sel(criterion=criteria, fraction=fractions, detector=detector)
                    .transpose("criterion", "fraction", "target")
                    .values
                    for ds in datasets
                ]
            ),
            dict(first[name].attrs),
        )
        for metric in METRICS
        for name in with_error(datasets, metric) + limit_flags(datasets, metric)
    }
    data["long_exposure_strehl"] = (
        ("case", "distance"),
        np.array([ds.long_exposure_strehl.sel(recentring="none", detector=detector).values for ds in datasets]),
        {"units": "1", "long_name": "long-exposure Strehl ratio without recentring"},
    )
    data["mean_true_rms_nm"] = (
        ("case", "distance"),
        np.array([ds.true_rms_nm.mean("frame").values for ds in datasets]),
        {"units": "nm", "long_name": "mean true tilt-removed residual rms along the target"},
    )
    data["reference_target"] = (
        "case",
        [int(ds.reference_target) for ds in datasets],
        {"units": "1", "long_name": "target that selects and recentres (-1: each its own)"},
    )
    return xr.Dataset(
        data,
        coords={
            **case_coords(settings, datasets),
            "criterion": ("criterion", criteria, {"long_name": "selection criterion"}),
            "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames selected"}),
            "distance": ("distance", distance, {"units": "arcsec", "long_name": "target's off-axis distance"}),
        },
        attrs={"detector": detector},
    )


def draw_quality_vs_distance(ds: xr.Dataset, title: str):
    n_rows = ds.sizes["criterion"]
    fig = new_figure(16, 3.6 * n_rows + 0.9)
    axes = fig.subplots(n_rows, 4, squeeze=False)
    for r, criterion in enumerate(ds.criterion.values):
        for ax, metric in zip(axes[r], METRICS):
            for case in ds.case.values:
                shade = colour(int(ds.colour.sel(case=case)))
                for k, fraction in enumerate(ds.fraction.values):
                    cell = ds.sel(case=case, criterion=criterion, fraction=fraction)
                    ax.plot(
                        ds.distance,
                        unflagged(cell, metric),
                        marker=MARKERS[k % 8],
                        ms=3.5,
                        color=shade,
                        ls=LINE_STYLES[k % 4],
                        label=f"{cell.label.values}, {100 * fraction:g} %",
                    )
                    band(ax, ds.distance, cell, metric, shade)
            ax.set_xlabel("off-axis distance [arcsec]")
            ax.set_ylabel(METRICS[metric])
            ax.grid(alpha=0.3)
        axes[r, 0].set_title(
            f"({chr(ord('a') + r)}) selection by {CRITERIA.get(criterion, criterion)}", loc="left", fontsize=10
        )
        axes[r, 3].set_visible(r == 0)
    ax = axes[0, 3]
    for case in ds.case.values:
        ax.plot(
            ds.distance,
            ds.mean_true_rms_nm.sel(case=case),
            marker="o",
            ms=3.5,
            color=colour(int(ds.colour.sel(case=case))),
            label=str(ds.label.sel(case=case).values),
        )
    ax.set_xlabel("off-axis distance [arcsec]")
    ax.set_ylabel("mean true tilt-removed rms [nm]")
    ax.set_title("residual wavefront along the target", loc="left", fontsize=10)
    ax.grid(alpha=0.3)
    fig.legend(
        *axes[0, 0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=3,
        fontsize=8,
        title="colour: case; line style and marker: fraction of frames\nimage criteria and recentring "
        "from the on-axis star, lgs_rms along each target\nbands: ±1 Monte-Carlo standard error" + _legend_note(ds),
        title_fontsize=8,
    )
    fig.suptitle(f"{title}: integrated-image quality vs off-axis distance ({ds.attrs['detector']} detector)")
    return fig


def quality_vs_parameter_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Integrated-image quality (first target) vs one swept parameter (``settings.parameter``,
    by default the sweep's first), a series per combination of the other parameters'
    values, per criterion and fraction, with Monte-Carlo errors."""
    points = settings.sweep_points
    paths = list(points[0][1])
    parameter = settings.parameter or paths[0]
    others = [p for p in paths if p != parameter]
    x_values = list(dict.fromkeys(values[parameter] for _, values in points))
    series = list(dict.fromkeys(tuple(values[p] for p in others) for _, values in points))
    where = {(tuple(v[p] for p in others), v[parameter]): i for i, (_, v) in enumerate(points)}
    criteria, fractions = list(settings.criteria), list(settings.fractions)
    dims = ("series", "x", "criterion", "fraction")
    data = {}
    for metric in METRICS:
        for name in with_error(datasets, metric):
            table = np.full((len(series), len(x_values), len(criteria), len(fractions)), np.nan)
            for s, key in enumerate(series):
                for j, x in enumerate(x_values):
                    ds = datasets[where[(key, x)]]
                    table[s, j] = (
                        ds[name]
                        .sel(criterion=criteria, fraction=fractions, detector=settings.detector)
                        .isel(target=0)
                        .values
                    )
            data[name] = (dims, table, dict(datasets[0][name].attrs))
    leaf = {p: p.rsplit(".", 1)[-1] for p in others}
    label = [", ".join(f"{leaf[p]} {v}" for p, v in zip(others, key)) or "all" for key in series]
    if all("transmitted_flux" in ds for ds in datasets):  # apodised cases: the pupil's blocked flux
        lost, error = np.full((len(series), len(x_values)), np.nan), np.full((len(series), len(x_values)), np.nan)
        for s, key in enumerate(series):
            for j, x in enumerate(x_values):
                ds = datasets[where[(key, x)]]
                lost[s, j], error[s, j] = flux_lost(ds.transmitted_flux.values, ds.sizes.get("block", 0))
        data["flux_lost"] = (
            ("series", "x"),
            lost,
            {"units": "1", "long_name": "mean fraction of the source's flux blocked by the apodisation"},
        )
        data["flux_lost_error"] = (
            ("series", "x"),
            error,
            {"units": "1", "long_name": "Monte-Carlo standard error of flux_lost (time blocks, batch means)"},
        )
    cases = [[points[where[(key, x)]][0] for x in x_values] for key in series]
    numeric = all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in x_values)
    return xr.Dataset(
        data,
        coords={
            "series": ("series", label, {"long_name": "the other parameters' values"}),
            "x": (
                "x",
                x_values if numeric else [str(x) for x in x_values],
                {"long_name": parameter, **({"units": key_units(parameter)} if numeric else {})},
            ),
            "criterion": ("criterion", criteria, {"long_name": "selection criterion"}),
            "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames selected"}),
            "case": (("series", "x"), cases, {"long_name": "the case of each point"}),
        },
        attrs={"detector": settings.detector, "parameter": parameter, "sweep": settings.sweep},
    )


def flux_lost(transmitted_flux: np.ndarray, n_blocks: int) -> tuple[float, float]:
    """1 - the mean transmitted flux per frame, and its batch-means error over ``n_blocks``
    time blocks (NaN with fewer than two)."""
    lost = 1.0 - np.asarray(transmitted_flux, dtype=float)
    return float(lost.mean()), batch_mean_error(lost, n_blocks) if n_blocks >= 2 else np.nan


def draw_quality_vs_parameter(ds: xr.Dataset, title: str):
    """A row per criterion: Strehl, FWHM and d50 vs the parameter (a colour per series, a line
    style per fraction); with apodised cases a fourth column, the flux lost (first row)."""
    n_rows, flux = ds.sizes["criterion"], "flux_lost" in ds
    fig = new_figure(13 + 4 * flux, 3.6 * n_rows + 1.0)
    axes = fig.subplots(n_rows, 3 + flux, squeeze=False)
    numeric = ds.x.dtype.kind in "iuf"
    axis = parameter(ds.attrs["parameter"])
    x = axis.scale * ds.x.values if numeric else np.arange(ds.sizes["x"])
    for r, criterion in enumerate(ds.criterion.values):
        for ax, metric in zip(axes[r], METRICS):
            series_fraction_lines(ax, x, ds.sel(criterion=criterion), metric)
            if not numeric:
                ax.set_xticks(x, ds.x.values)
            ax.set_xlabel(axis.label())
            ax.set_ylabel(METRICS[metric])
            ax.grid(alpha=0.3)
        letter = f"({chr(ord('a') + r)}) " if n_rows > 1 else ""
        axes[r, 0].set_title(f"{letter}selection by {CRITERIA.get(criterion, criterion)}", loc="left", fontsize=10)
        if flux:
            axes[r, 3].set_visible(r == 0)
    if flux:
        ax = axes[0, 3]
        for s, series in enumerate(ds.series.values):
            cell = ds.sel(series=series)
            ax.errorbar(
                x,
                cell.flux_lost.values,
                yerr=cell.flux_lost_error.values,
                color=colour(s),
                marker="o",
                ms=4,
                capsize=2,
                lw=1.2,
            )
        ax.set_xlabel(axis.label())
        ax.set_ylabel("flux lost (fraction of the source's)")
        ax.set_title("flux blocked by the apodisation", loc="left", fontsize=9)
        ax.grid(alpha=0.3)
    fig.legend(
        *axes[0, 0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=ds.sizes["fraction"],
        fontsize=8,
        title="colour: the sweep's other parameters; line style and marker: fraction of frames "
        "selected\nerror bars: ±1 Monte-Carlo standard error",
        title_fontsize=8,
    )
    fig.suptitle(
        f"{title}: integrated-image quality vs {axis.name} (sweep {ds.attrs['sweep']}, {ds.attrs['detector']} detector)"
    )
    return fig


def comparisons_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Paired differences ``a - b`` of integrated-image quality vs fraction: two cases (or
    two criteria of one case) that share the turbulence, so the Monte-Carlo error of the
    difference comes from the per-time-block differences (paired), far below the
    unpaired ``sqrt(e_a^2 + e_b^2)`` that the errors of each curve would suggest."""
    by_name = dict(zip(settings.cases, datasets))
    pairs = settings.pairs
    data = {}
    for metric, long_name in METRICS.items():
        value, paired, unpaired = [], [], []
        for pair in pairs:
            a, b = (
                by_name[pair[k]["case"]][[metric, f"{metric}_error", f"{metric}_block"]]
                .sel(criterion=pair[k]["criterion"], detector=settings.detector)
                .isel(target=0)
                for k in ("a", "b")
            )
            if a.sizes["block"] != b.sizes["block"]:
                raise ValueError(f"pair {pair['label']}: {a.sizes['block']} and {b.sizes['block']} time blocks")
            blocks = (a[f"{metric}_block"] - b[f"{metric}_block"]).values  # (block, fraction)
            value.append((a[metric] - b[metric]).values)
            paired.append(block_error(blocks))
            unpaired.append(np.hypot(a[f"{metric}_error"].values, b[f"{metric}_error"].values))
        units = datasets[0][metric].attrs["units"]
        dims = ("pair", "fraction")
        data[metric] = (dims, np.array(value), {"units": units, "long_name": f"difference a - b: {long_name}"})
        data[f"{metric}_error"] = (
            dims,
            np.array(paired),
            {"units": units, "long_name": "paired Monte-Carlo standard error of the difference (time blocks)"},
        )
        data[f"{metric}_unpaired_error"] = (
            dims,
            np.array(unpaired),
            {"units": units, "long_name": "unpaired error sqrt(e_a^2 + e_b^2), for comparison"},
        )
    return xr.Dataset(
        data,
        coords={
            "pair": ("pair", [p["label"] for p in pairs], {"long_name": "difference a - b"}),
            "a": ("pair", [f"{p['a']['case']} by {p['a']['criterion']}" for p in pairs], {"long_name": "case a"}),
            "b": ("pair", [f"{p['b']['case']} by {p['b']['criterion']}" for p in pairs], {"long_name": "case b"}),
            "fraction": datasets[0]["fraction"],
        },
        attrs={"detector": settings.detector},
    )


def draw_comparisons(ds: xr.Dataset, title: str):
    fig = new_figure(15, 5.0)
    axes = fig.subplots(1, 3, squeeze=False)
    x = 100 * ds.fraction.values
    for ax, metric in zip(axes[0], METRICS):
        for k, pair in enumerate(ds.pair.values):
            row, shade = ds.sel(pair=pair), colour(k)
            ax.plot(x, row[metric], marker=MARKERS[k % len(MARKERS)], ms=3.5, color=shade, label=str(pair))
            band(ax, x, row, metric, shade)
            for sign in (-1, 1):
                ax.plot(x, row[metric] + sign * row[f"{metric}_unpaired_error"], color=shade, lw=0.6, ls=":")
        ax.axhline(0.0, color="k", lw=0.8)
        fraction_axis(ax)
        ax.set_ylabel(f"difference of {METRICS[metric]}")
        ax.grid(alpha=0.3)
    fig.legend(
        *axes[0, 0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=4,
        fontsize=8,
        title="colour and marker: difference a - b\nbands: paired ±1 standard error (time blocks, shared turbulence); "
        "dotted: unpaired ±1 standard error",
        title_fontsize=8,
    )
    fig.suptitle(f"{title}: paired differences of integrated-image quality ({ds.attrs['detector']} detector)")
    return fig
