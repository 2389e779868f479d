"""The Snakemake workflow end to end on a tiny study: outputs, provenance,
incremental reruns and config errors."""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from luckyao.photometry import Photometry, collecting_area_m2

from studies import REPO, TINY, snakemake, with_sweep

pytestmark = pytest.mark.workflow  # runs Snakemake, a study or the command line: -m 'not workflow' skips it


def write_config(workdir: Path, study: dict | None = None) -> Path:
    """The workdir's study config: the tiny study, or ``study``."""
    path = workdir / "config" / "config.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    if study is None:
        shutil.copy(TINY, path)
    else:
        path.write_text(yaml.safe_dump(study))
    return path


def baseline(path: Path) -> xr.Dataset:
    """A case's ``lucky.nc``, its baseline registration (``cog``)."""
    return xr.open_dataset(path).sel(registration="cog")


def jobs_planned(result) -> list[tuple[str, str]]:
    """(rule, wildcards) of every job a dry run would execute."""
    jobs, rule = [], None
    for line in result.stdout.splitlines():
        line = line.strip()
        if line.startswith(("rule ", "localrule ")):
            rule = line.split()[1].rstrip(":")
            jobs.append((rule, ""))
        elif line.startswith("wildcards:") and jobs:
            jobs[-1] = (rule, line.split(":", 1)[1].strip())
    return jobs


def planned_after_edit(workdir: Path, study: dict) -> list[tuple[str, str]]:
    """(rule, wildcards) of every job a dry run of the edited ``study`` (an overlay over the
    workdir's config) would execute."""
    edited = workdir / "edited.yaml"
    edited.write_text(yaml.safe_dump(study))
    result = snakemake(workdir, "--dry-run", "--configfile", str(edited))
    assert result.returncode == 0, result.stderr
    return jobs_planned(result)


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    workdir = tmp_path_factory.mktemp("study")
    config = write_config(workdir)
    result = snakemake(workdir)
    assert result.returncode == 0, result.stderr[-3000:]
    return workdir, config


def test_tiny_study_makes_every_figure_with_provenance(finished_run):
    workdir, _ = finished_run
    for fig in ("quality", "longexp", "lgsrms", "residuals", "table", "noise", "onaxis", "paired", "registration"):
        for ext in ("pdf", "png", "nc"):
            assert (workdir / "figures" / f"{fig}.{ext}").stat().st_size > 0
    lucky = baseline(workdir / "results" / "cases" / "good" / "lucky.nc")
    config = json.loads(lucky.attrs["config_json"])
    assert config["atmosphere"]["r0_500nm_m"] == 0.2
    assert len(lucky.attrs["config_sha256"]) == 64 and lucky.attrs["seed"] == 7
    assert lucky.attrs["code_version"]
    for name in ("strehl", "fwhm_arcsec", "d50_arcsec", "long_exposure_strehl"):
        assert "units" in lucky[name].attrs and "long_name" in lucky[name].attrs
    assert set(lucky.criterion.values) >= {"strehl", "d50"}
    assert sorted(lucky.detector.values) == ["faint", "noiseless"]
    # frame cubes are temporary by default
    assert not (workdir / "results" / "cases" / "good" / "frames.nc").exists()
    longexp = xr.open_dataset(workdir / "figures" / "longexp.nc")
    assert list(longexp.case.values) == ["good", "bad"]
    assert list(longexp.r0_cm.values) == pytest.approx([20.0, 10.0])
    assert {"simulated", "analytic"} <= set(longexp.data_vars)


def test_a_field_star_selecting_itself_is_the_single_target_case(finished_run):
    """The field case's on-axis star (target 0, its own reference) gives exactly the
    single-target case's results; the off-axis targets, replayed rather than stored,
    get results too. The two cases' simulations replay one LGS slopes product (another
    asterism, ``ltao_turned``, has its own): three AO cases, two measurements."""
    workdir, _ = finished_run
    assert len(list((workdir / "results" / "benchmarks" / "slopes").glob("slopes_*.tsv"))) == 2
    single = baseline(workdir / "results" / "cases" / "ltao" / "lucky.nc")
    field = baseline(workdir / "results" / "cases" / "field" / "lucky.nc")
    assert field.sizes["target"] == 3 and int(field.reference_target) == 0
    compared = 0
    for name, var in single.data_vars.items():
        if "target" in var.dims and name in field:
            np.testing.assert_array_equal(field[name].isel(target=0).values, var.isel(target=0).values, err_msg=name)
            compared += 1
    assert compared >= 15
    assert np.isfinite(field.strehl.sel(detector="noiseless").values).all()
    onaxis = xr.open_dataset(workdir / "figures" / "onaxis.nc")
    assert list(onaxis.distance.values) == [0.0, 10.0, 20.0]


def test_every_quality_value_carries_its_error_and_paired_differences_are_tighter(finished_run):
    """Each lucky value has a Monte-Carlo error from time blocks, carried into the figures'
    data. Turning the four-LGS asterism by 90 degrees gives the same asterism (beacons
    relabelled): its difference from the unturned case cannot matter, so the paired
    error (per-block differences over the shared turbulence) covers it and is far
    below the unpaired one."""
    workdir, _ = finished_run
    lucky = baseline(workdir / "results" / "cases" / "ltao" / "lucky.nc")
    for metric in ("strehl", "fwhm_arcsec", "d50_arcsec"):
        assert lucky[f"{metric}_block"].sizes["block"] == 4
        error = lucky[f"{metric}_error"].sel(detector="noiseless").values
        assert np.isfinite(error).all() and (error > 0).any()
    quality = xr.open_dataset(workdir / "figures" / "quality.nc")
    assert "strehl_error" in quality and "d50_arcsec_error" in quality
    paired = xr.open_dataset(workdir / "figures" / "paired.nc").sel(pair="turned asterism")
    difference, error, unpaired = (paired[v].values for v in ("strehl", "strehl_error", "strehl_unpaired_error"))
    assert (np.abs(difference) <= 2 * error).all(), (difference, error)
    assert (error < 0.2 * unpaired).all(), (error, unpaired)


def test_nothing_to_do_after_a_run(finished_run):
    workdir, config = finished_run
    result = snakemake(workdir, "--dry-run")
    assert result.returncode == 0, result.stderr
    assert jobs_planned(result) == []


def test_editing_one_case_reruns_only_that_case(finished_run):
    workdir, config = finished_run
    study = yaml.safe_load(config.read_text())
    study["cases"]["bad"]["atmosphere"]["r0_500nm_m"] = 0.12
    jobs = planned_after_edit(workdir, study)
    cases = {w for rule, w in jobs if rule in ("simulate", "lucky")}
    assert cases == {"case=bad"}
    assert not any(rule == "turbulence" for rule, _ in jobs)
    assert {w for rule, w in jobs if rule == "figure"} == {"fig=quality", "fig=longexp"}


def test_a_no_ao_case_takes_its_lgs_rms_from_its_twin_and_survives_the_twins_ao_edits(finished_run):
    """The no-AO case ``lgs`` takes its ``lgs_rms`` from ``ltao`` (same LGS chain): bit-identical
    to ``ltao``'s; an edit of ``ltao``'s AO alone reruns ``ltao``, not ``lgs`` (the twin's
    telemetry is an ``ancient`` input: what sets ``lgs_rms`` is ``lgs``'s own config)."""
    workdir, config = finished_run
    own = xr.open_dataset(workdir / "results" / "cases" / "lgs" / "telemetry.nc")
    twin = xr.open_dataset(workdir / "results" / "cases" / "ltao" / "telemetry.nc")
    np.testing.assert_array_equal(own.lgs_rms_nm.values, twin.lgs_rms_nm.values)
    assert not np.array_equal(own.true_rms_nm.values, twin.true_rms_nm.values)  # not the same case
    study = yaml.safe_load(config.read_text())
    study["cases"]["ltao"]["ao"]["coupling"] = 0.25
    assert {w for rule, w in planned_after_edit(workdir, study) if rule in ("simulate", "lucky")} == {"case=ltao"}


def test_invalid_config_fails_before_any_job_naming_the_key(tmp_path):
    study = yaml.safe_load(TINY.read_text())
    study["cases"]["good"]["atmosphere"]["r0_500nm_m"] = -0.2
    write_config(tmp_path, study)
    result = snakemake(tmp_path, "--dry-run")
    assert result.returncode != 0
    message = result.stdout + result.stderr
    assert "cases.good.atmosphere.r0_500nm_m" in message
    assert not (tmp_path / "results").exists()


def test_a_hard_kill_mid_study_is_recovered_by_the_study_command(finished_run, tmp_path):
    """SIGKILL of Snakemake and its jobs while a simulation runs leaves a stale lock;
    the README's study command (``run.sh study``) alone then finishes the study, leaves
    no ``*.partial`` file, and gives the numbers of an uninterrupted run (the same
    tiny study in ``finished_run``). The killed study is that run with one case's
    results, logs and figures taken away (copied with their times and Snakemake's records),
    so only that case and its figures run again."""
    done, config = finished_run
    workdir = tmp_path / "killed"
    shutil.copytree(done, workdir, symlinks=True)  # copy2: modification times kept
    shutil.rmtree(workdir / "results" / "cases" / "good")
    figures = [
        fig
        for fig, spec in yaml.safe_load(config.read_text())["figures"].items()
        if "good" in (spec.get("cases") or [])
    ]
    assert figures
    for path in [*workdir.glob("logs/*/good.log"), *(p for fig in figures for p in workdir.glob(f"figures/{fig}.*"))]:
        path.unlink()
    assert not list((workdir / "results").rglob("*.partial"))
    command = ["bash", str(REPO / "run.sh"), "study", "-d", str(workdir), "--cores", "2"]
    first = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    simulating = workdir / "logs" / "simulate" / "good.log"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and not simulating.exists():
        time.sleep(0.2)
    time.sleep(1.0)  # inside the time loop
    os.killpg(first.pid, signal.SIGKILL)
    first.wait()
    assert any((workdir / ".snakemake" / "locks").iterdir()), "the kill left no lock: the test proves nothing"
    result = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "case=good" in result.stdout + result.stderr, "the recovery did not run the killed case again"
    assert not list((workdir / "results").rglob("*.partial"))
    compared = sorted((done / "results" / "cases").glob("*/lucky.nc")) + sorted((done / "figures").glob("*.nc"))
    assert compared
    for path in compared:
        expected = xr.open_dataset(path)
        got = xr.open_dataset(workdir / path.relative_to(done))
        for name in expected.data_vars:
            np.testing.assert_array_equal(got[name].values, expected[name].values, err_msg=f"{path.name}: {name}")


def test_a_command_line_override_is_applied_not_ignored(finished_run):
    """``--config seed=5`` changes the seed every product derives from: the dry run plans
    new screens and reruns every case; an override that breaks the schema is refused."""
    workdir, _ = finished_run
    result = snakemake(workdir, "--dry-run", "--config", "seed=5")
    assert result.returncode == 0, result.stderr
    rules = {rule for rule, _ in jobs_planned(result)}
    assert {"turbulence", "simulate", "lucky", "figure"} <= rules
    refused = snakemake(workdir, "--dry-run", "--config", "seed=-1")
    assert refused.returncode != 0 and "config key 'seed'" in refused.stdout + refused.stderr


def test_names_that_would_reach_the_shell_or_leave_the_folder_create_nothing(tmp_path):
    """A figure named to run a command or to write outside the study folder (an asterism
    figure: its job needs no other job) is refused before any job: nothing is created."""
    study = yaml.safe_load(TINY.read_text())
    asterism = {"kind": "asterism", "cases": ["lgs"], "layer_heights_m": [0, 5000]}
    study["figures"] = {"q$(touch PWNED)": asterism, "../../X": asterism}
    workdir = tmp_path / "a" / "b"
    write_config(workdir, study)
    result = snakemake(workdir)
    assert result.returncode != 0
    assert "is not a safe name" in result.stdout + result.stderr
    created = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if not p.is_dir())
    assert [p for p in created if ".snakemake" not in p.parts] == [Path("a/b/config/config.yaml")]


def test_every_value_formatted_into_a_shell_command_is_quoted():
    """Each ``{...}`` of every rule's shell command is quoted (``:q``), but the command
    prefix (quoted where it is made) and the integers."""
    unquoted, checked = {"LUCKYAO", "threads", "params.seed"}, 0
    for path in sorted((REPO / "workflow" / "rules").glob("*.smk")):
        text = path.read_text()
        for shell in re.findall(r"shell:\n((?:\s+\".*\"\n?)+)", text):
            for field in re.findall(r"\{([^{}]+)\}", shell):
                assert field.endswith(":q") or field in unquoted, f"{path.name}: {{{field}}} is not quoted"
                checked += 1
    assert checked >= 25


@pytest.mark.parametrize("what", ["duration", "wfs"])
def test_a_study_too_large_for_this_machine_is_refused_before_any_job(tmp_path, what):
    """1e7 s of screens (1.2 TB) or a 1000 x 1000 WFS (its slope covariance alone 8e14 bytes)
    is refused with the job and the numbers, in seconds, before any job (a dry run: on
    the old code this planned the jobs); the files of the study are summed against the disk."""
    study = yaml.safe_load(TINY.read_text())
    if what == "duration":
        study["turbulence"]["duration_s"] = study["base"]["duration_s"] = 1e7
        expected = (
            r"the study's files not yet made need about [\d,.]+ GB together \(.*phase screens [\d,.]+ GB.*\), "
            r"more than the [\d,.]+ GB free"
        )
    else:
        study["cases"]["lgs"]["wfs"] = {"n_subapertures": 1000}
        expected = r"job reconstructor reconstructor_\w+ needs about [\d,.]+ GB of memory, more than the [\d,.]+ GB"
    write_config(tmp_path, study)
    result = snakemake(tmp_path, "--dry-run")
    assert result.returncode != 0
    assert re.search(expected, result.stdout + result.stderr), result.stderr[-2000:]
    assert not (tmp_path / "results").exists()


def test_a_sweep_figure_draws_every_point_and_a_new_value_reruns_only_its_case(finished_run):
    """The tiny study's sweep over r0 (0.2 m: the case good; 0.15 m: a case of its own)
    is drawn with each point's values from its case; adding a value plans only the new
    case's jobs and the figures that show it."""
    workdir, config = finished_run
    sweep = xr.open_dataset(workdir / "figures" / "sweep.nc")
    assert list(sweep.x.values) == [0.2, 0.15]
    assert list(sweep.case.values.ravel()) == ["good", "r0_r0_500nm_m-0.15"]
    for j, case in enumerate(sweep.case.values.ravel()):
        lucky = baseline(workdir / "results" / "cases" / case / "lucky.nc")
        expected = lucky.sel(criterion="strehl", detector="noiseless", fraction=[0.1, 1.0]).isel(target=0)
        for name in ("strehl", "strehl_error", "d50_arcsec"):
            np.testing.assert_array_equal(
                sweep[name].isel(series=0, x=j).sel(criterion="strehl").values, expected[name].values
            )
    study = yaml.safe_load(config.read_text())
    study["sweeps"]["r0"]["parameters"]["atmosphere.r0_500nm_m"].append(0.3)
    jobs = planned_after_edit(workdir, study)
    assert {w for rule, w in jobs if rule in ("simulate", "lucky", "export")} == {"case=r0_r0_500nm_m-0.3"}
    assert {w for rule, w in jobs if rule == "figure"} == {"fig=sweep"}


def test_a_sweep_figures_points_keep_the_sweeps_parameter_order(tmp_path):
    """A sweep figure without ``parameter`` draws against the sweep's first parameter: its
    points reach the figure with their values in the sweep's order (before: sorted as text by
    the settings' canonical JSON, ``ao.mode`` before ``atmosphere.r0_500nm_m``)."""
    from luckyao.figures.settings import FigureSettings

    study = with_sweep({"atmosphere.r0_500nm_m": [0.2, 0.15], "ao.mode": ["none"]})
    write_config(tmp_path).write_text(yaml.safe_dump(study, sort_keys=False))  # the sweep's order kept
    result = snakemake(tmp_path, "--dry-run")
    assert result.returncode == 0, result.stderr[-3000:]
    [path] = (tmp_path / "results" / "figures" / "settings").glob("grid_*.json")
    settings = FigureSettings.from_dict(json.loads(path.read_text()))
    assert [list(values) for _, values in settings.sweep_points] == [["atmosphere.r0_500nm_m", "ao.mode"]] * 2


def test_fits_images_read_back_with_their_header_and_flux(finished_run):
    """Every image of a case's lucky.nc is an extension of fits/<case>.fits with its pixels,
    quality and errors, provenance and a WCS in arcsec; the tiny study keeps the whole
    64-pixel frame, whose pixels are over its flux: each image sums to 1."""
    from astropy.io import fits
    from astropy.wcs import WCS

    workdir, _ = finished_run
    lucky = baseline(workdir / "results" / "cases" / "good" / "lucky.nc")
    with fits.open(workdir / "fits" / "good.fits") as hdus:
        per_detector = lucky.sizes["criterion"] * lucky.sizes["fraction"] + lucky.sizes["recentring"]
        assert hdus[0].header["NIMAGES"] == len(hdus) - 2 == per_detector * lucky.sizes["detector"]  # - INDEX
        for detector in lucky.detector.values:
            cell = lucky.sel(criterion="strehl", fraction=0.1, detector=detector).isel(target=0)
            image = hdus[f"LUCKY_T0_COG_STREHL_0.1_{detector.upper()}"]
            np.testing.assert_array_equal(image.data, cell.image.values)
            for key, name in (
                ("STREHL", "strehl"),
                ("STREHLE", "strehl_error"),
                ("FWHM", "fwhm_arcsec"),
                ("D50", "d50_arcsec"),
                ("D50E", "d50_arcsec_error"),
            ):
                assert image.header[key] == pytest.approx(float(cell[name]), rel=1e-15), key  # a card's 20 digits
            assert image.header["FLUXFRAC"] == pytest.approx(1.0, abs=1e-5)
            assert float(image.data.sum(dtype=np.float64)) == pytest.approx(1.0, abs=1e-5)
            assert image.header["DETECTOR"] == detector and image.header["CRITERIO"] == "strehl"
        header = hdus["LONG_T0_NONE_NOISELESS"].header
        assert header["STREHL"] == pytest.approx(
            float(lucky.long_exposure_strehl.sel(recentring="none", detector="noiseless").isel(target=0)), rel=1e-15
        )
        assert header["STREHLE"] == pytest.approx(float(lucky.long_exposure_strehl_error.isel(target=0)), rel=1e-15)
        assert header["CFGHASH"] == lucky.attrs["config_sha256"] and header["SEED"] == 7
        assert header["CODEVER"] == lucky.attrs["code_version"][:68] and header["WAVELENG"] == 8e-7
        # the WCS puts the optical axis (pixel n/2 of the frame) at offset 0 and a pixel at 1.25"/64
        wcs = WCS(header)
        assert wcs.pixel_to_world_values(32, 32) == pytest.approx((0.0, 0.0))
        assert wcs.pixel_to_world_values(33, 32)[0] == pytest.approx(1.25 / 64)


def _image_of(lucky: xr.Dataset, row) -> np.ndarray:
    """The image of lucky.nc that an ``INDEX`` row of its FITS file names."""
    if row["IMAGETYP"] == "lucky":
        cell = lucky.image.sel(registration=row["REGISTR"], criterion=row["CRITERIO"], fraction=row["FRACTION"])
    else:
        recentred = row["RECENTR"] != "none"
        method = row["REGISTR"] if recentred else lucky.registration.values[0]
        cell = lucky.long_exposure_image.sel(registration=method, recentring="cog" if recentred else "none")
    return cell.sel(detector=row["DETECTOR"]).isel(target=row["TARGET"]).values


def test_fits_headers_are_standard_and_index_every_image_of_every_registration(finished_run, tmp_path):
    """fits/<case>.fits of the noise figures' case: every image of lucky.nc, every registration
    method (before: cog alone, no keyword saying so), bit for bit, found through the INDEX table
    (extension 1), with a BUNIT astropy's FITS parser reads (before: '1'), DATE, EXPTIME (the
    selected frames' exposure), PHOTONS a number or absent for the noiseless detector (before:
    the string 'none'), the noise-dominated flags of lucky.nc; the cube layout holds the same
    images, the fraction along its third axis."""
    import astropy.units as u
    from astropy.io import fits
    from astropy.time import Time

    from luckyao.cli import main

    workdir, _ = finished_run
    lucky = xr.open_dataset(workdir / "results" / "cases" / "lgs" / "lucky.nc")
    cube_path = tmp_path / "cube.fits"
    assert (
        main(["export", str(workdir / "results" / "cases" / "lgs" / "lucky.nc"), "--out", str(cube_path), "--cube"])
        == 0
    )
    with fits.open(workdir / "fits" / "lgs.fits") as hdus, fits.open(cube_path) as cubes:
        index = hdus[hdus[0].header["INDEXHDU"]].data
        assert hdus[1].name == "INDEX" and len(index) == hdus[0].header["NIMAGES"] == len(hdus) - 2
        assert set(index["REGISTR"]) - {""} == set(lucky.registration.values) == {"cog", "xcorr"}
        frame_time = hdus[0].header["FRAMETIM"]
        assert Time(hdus[0].header["DATE"], format="isot", scale="utc")
        for row in index:
            hdu = hdus[int(row["HDU"])]
            header = hdu.header
            assert hdu.name == row["EXTNAME"] and header.get("REGISTR", "") == row["REGISTR"]
            pixels = hdu.data.astype(np.float32)  # FITS's big-endian floats as the native ones, exactly
            assert pixels.tobytes() == _image_of(lucky, row).astype(np.float32).tobytes()
            assert u.Unit(header["BUNIT"], format="fits") == u.dimensionless_unscaled
            assert header["EXPTIME"] == pytest.approx(header["NCOMBINE"] * frame_time, rel=1e-12)
            noiseless = not np.isfinite(float(lucky.photons_per_frame.sel(detector=row["DETECTOR"])))
            assert header["NOISELES"] is noiseless and ("PHOTONS" in header) is not noiseless
            assert noiseless or isinstance(header["PHOTONS"], float)
            if row["IMAGETYP"] == "lucky":
                cell = lucky.sel(
                    registration=row["REGISTR"],
                    criterion=row["CRITERIO"],
                    fraction=row["FRACTION"],
                    detector=row["DETECTOR"],
                ).isel(target=row["TARGET"])
                assert header["NCOMBINE"] == int(cell.n_frames_selected)
                assert header["STREHLND"] is bool(cell.strehl_noise_dominated) is bool(row["STREHLND"])
                cube = cubes[f"LUCKY_T0_{row['REGISTR']}_{row['CRITERIO']}_{row['DETECTOR']}".upper()]
                plane = list(lucky.fraction.values).index(row["FRACTION"])
                assert cube.header[f"FRAC{plane + 1}"] == row["FRACTION"]
                assert cube.data[plane].tobytes() == hdu.data.tobytes()
        assert cubes[0].header["NIMAGES"] == len(index) and cubes[0].header["LAYOUT"] == "cube"


def test_lucky_files_store_detectors_by_signal_and_flag_noise_dominated_values(finished_run):
    """lucky.nc's detectors: the noiseless first, then by read noise and photons per frame (before:
    as text, 'faint' (1000 photons) before 'noiseless' and 'rn0.1_100ph'); each metric's
    ``<metric>_noise_dominated`` is 1 where it is more than 30 % off the noiseless frames' value,
    every Strehl above 1 among them."""
    workdir, _ = finished_run
    lgs = xr.open_dataset(workdir / "results" / "cases" / "lgs" / "lucky.nc")
    assert list(lgs.detector.values) == ["noiseless", "rn0.1_100ph", "faint", "rn0.1_1e+04ph"]
    for metric in ("strehl", "fwhm_arcsec", "d50_arcsec"):
        value, clean = lgs[metric], lgs[f"{metric}_noiseless"]
        expected = ~(np.abs(value - clean) <= 0.3 * np.abs(clean))
        np.testing.assert_array_equal(lgs[f"{metric}_noise_dominated"].values, expected.values.astype(np.int8))
    assert (lgs.strehl_noise_dominated.values[lgs.strehl.values > 1] == 1).all()


def test_every_dataset_has_cf_attributes_with_udunits_units(finished_run):
    """Every variable and coordinate of every dataset the study writes (results/**/*.nc,
    figures/*.nc) has a long_name (or a standard_name), every numeric one units, and every unit
    parses in UDUNITS-2 (cf-units; before: 'photon', 'electron', 'pixel', and the registration
    figure without attributes)."""
    import cf_units
    import netCDF4

    workdir, _ = finished_run
    paths = sorted(workdir.glob("results/**/*.nc")) + sorted(workdir.glob("figures/*.nc"))
    assert len(paths) > 20 and any(p.name == "registration.nc" for p in paths)
    problems = []
    for path in paths:
        with netCDF4.Dataset(path) as ds:
            for name, variable in ds.variables.items():
                attrs = set(variable.ncattrs())
                where = f"{path.relative_to(workdir)}: {name}"
                if not attrs & {"long_name", "standard_name"}:
                    problems.append(f"{where}: no long_name")
                if variable.dtype != str and "units" not in attrs:
                    problems.append(f"{where}: no units")
                if "units" in attrs:
                    try:
                        cf_units.Unit(variable.units)
                    except ValueError:
                        problems.append(f"{where}: units {variable.units!r} not UDUNITS")
    assert not problems, "\n".join(problems)


def test_the_psf_gallery_shows_each_image_in_units_of_the_diffraction_limited_peak(finished_run):
    """The gallery's images are the cases' images over the diffraction-limited peak, so each
    panel's brightest pixel is its Strehl ratio; the long exposure comes first."""
    workdir, _ = finished_run
    gallery = xr.open_dataset(workdir / "figures" / "psf.nc")
    assert list(gallery.case.values) == ["good", "ltao"]
    assert list(gallery.panel.values) == ["long exposure", "image Strehl, 100 %", "image Strehl, 10 %"]
    brightest = gallery.image.max(("y", "x")).values
    np.testing.assert_allclose(brightest, gallery.strehl.values, rtol=1e-5)
    ltao = baseline(workdir / "results" / "cases" / "ltao" / "lucky.nc")
    assert float(gallery.strehl.sel(case="ltao", panel="image Strehl, 10 %")) == float(
        ltao.strehl.sel(criterion="strehl", fraction=0.1, detector="noiseless").isel(target=0)
    )


def test_the_python_api_opens_results_and_reruns_a_case_to_the_same_numbers(finished_run, tmp_path):
    """``luckyao.open_case`` / ``open_figure`` give the study's files; ``run_case`` on the
    tiny study's config runs a case without Snakemake to the workflow's very numbers."""
    import luckyao

    workdir, config = finished_run
    lucky = luckyao.open_case("good", workdir)
    assert lucky.identical(xr.load_dataset(workdir / "results" / "cases" / "good" / "lucky.nc"))
    figure = luckyao.open_figure("quality", workdir)
    assert figure.identical(xr.load_dataset(workdir / "figures" / "quality.nc"))
    assert len(luckyao.draw(figure).axes) == 3
    rerun = luckyao.run_case(luckyao.load_study(config), "good", workdir=tmp_path)
    for name in ("strehl", "d50_arcsec", "strehl_error", "image", "long_exposure_strehl", "frame_strehl"):
        np.testing.assert_array_equal(rerun[name].values, lucky[name].values, err_msg=name)
    with pytest.raises(FileNotFoundError, match="nope"):
        luckyao.open_case("nope", workdir)


def test_the_report_has_short_captions_and_no_settings_json(finished_run):
    """Each caption says what the figure shows, its cases in short and its short config
    hash; no figure job carries the settings JSON (formerly 5-28k characters a caption)."""
    workdir, _ = finished_run
    result = snakemake(workdir, "--report", str(workdir / "report.html"))
    assert result.returncode == 0, result.stderr[-3000:]
    html = (workdir / "report.html").read_text()
    assert "case_configs" not in html and "settings={" not in html
    assert "Integrated-image quality vs a swept parameter" in html
    assert "no AO, 4.2 m, r0 20 cm" in html  # the case good, in short


def test_registration_methods_along_their_dimension_and_the_knees(finished_run):
    """The noise figures' case holds every registration method along ``registration`` (cog the
    baseline among them, each frame registered or counted), the others cog alone; the
    registration figure's dataset has a knee per curve and ``luckyao knees`` prints them."""
    workdir, _ = finished_run
    lgs = xr.open_dataset(workdir / "results" / "cases" / "lgs" / "lucky.nc")
    assert list(lgs.registration.values) == ["cog", "xcorr"]
    registered = np.isfinite(lgs.frame_registered_px).all("axis").sum("frame")
    assert ((registered + lgs.unregistered_frames) == lgs.sizes["frame"]).all()
    cog = lgs.sel(registration="cog")
    np.testing.assert_array_equal(cog.frame_registered_px, cog.frame_centroid_px)
    good = xr.open_dataset(workdir / "results" / "cases" / "good" / "lucky.nc")
    assert list(good.registration.values) == ["cog"]
    figure = xr.open_dataset(workdir / "figures" / "registration.nc")
    assert list(figure.registration.values) == ["cog", "xcorr"]
    assert figure.strehl_knee_photons.dims == ("registration", "case", "criterion", "fraction", "read_noise")
    result = subprocess.run(
        [sys.executable, "-m", "luckyao", "knees", str(workdir / "figures" / "registration.nc")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert "| xcorr |" in result.stdout and "| cog |" in result.stdout
    limiting = xr.open_dataset(workdir / "figures" / "limiting.nc")  # the same knees, as magnitudes at 4.2 m
    for metric in ("strehl", "d50_arcsec"):
        knee = figure[f"{metric}_knee_photons"].sel(case="lgs", criterion=["strehl"])
        np.testing.assert_array_equal(limiting[f"{metric}_knee_photons"].isel(series=0, diameter=0), knee)
        np.testing.assert_allclose(
            limiting[f"{metric}_knee_i_mag"].isel(series=0, diameter=0),
            Photometry.from_config().magnitude(knee, collecting_area_m2(4.2, 1.2), 0.01),
        )


def test_without_frame_cubes_every_result_is_the_stored_cubes_bit_for_bit(finished_run, tmp_path):
    """``replay_frames``: the simulation images nothing and writes no cube; every lucky job makes
    its frames again from the screens and the recorded DM commands as it reads them (every pass).
    Every variable of every case's ``lucky.nc`` (each detector, noisy and noiseless, each
    registration method, the field's replayed targets) equals the stored-cube run's, but
    ``imaged`` (the targets whose frames the simulation wrote: none here)."""
    workdir, config = finished_run
    study = yaml.safe_load(config.read_text())
    study["replay_frames"] = True
    write_config(tmp_path, study)
    stored_cases = sorted((workdir / "results" / "cases").glob("*/lucky.nc"))
    assert len(stored_cases) >= 7
    # the lucky datasets only: a figure is drawn from them by the same code in both runs
    result = snakemake(tmp_path, *(str(path.relative_to(workdir)) for path in stored_cases))
    assert result.returncode == 0, result.stderr[-3000:]
    assert "frames.nc" not in result.stdout + result.stderr  # no job ever plans a cube
    for stored in stored_cases:
        replayed = tmp_path / stored.relative_to(workdir)
        with xr.open_dataset(stored) as a, xr.open_dataset(replayed) as b:
            assert set(a.variables) == set(b.variables), stored
            for name in set(a.variables) - {"imaged"}:
                np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=f"{stored}: {name}")
    for telemetry in (tmp_path / "results" / "cases").glob("*/telemetry.nc"):
        with xr.open_dataset(telemetry) as ds:
            assert not ds.imaged.values.any(), telemetry  # the simulation imaged nothing


def test_a_figure_asked_for_alone_exports_its_cases_fits(tmp_path):
    """``bash run.sh study figures/quality.png``: the figure's cases' FITS images come with it."""
    write_config(tmp_path)
    result = snakemake(tmp_path, "--dry-run", "figures/quality.png")
    assert result.returncode == 0, result.stderr
    assert {w for rule, w in jobs_planned(result) if rule == "export"} == {"case=good", "case=bad"}
