"""The last ways in (issue 40): every config that cannot run to the end is refused before any
job, naming the key or the file, by `luckyao check` and the workflow alike: names whole and
short enough for a file name, detector and sweep names that cannot collide, seeds, labels
matplotlib can draw, strict YAML (no alias bombs, duplicate keys or a top level that is not
a mapping), bounded grids, and one pre-flight of memory and of the disk the study's files
need together."""

import json
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from luckyao.cli import main
from luckyao.jobs import resources
from luckyao.jobs.resources import preflight, study_jobs
from luckyao.studyspec.lucky import sweep_detectors
from luckyao.studyspec.schema import ConfigError
from luckyao.studyspec.study import load_study, validate_study
from luckyao.studyspec.sweeps import expand_study
from luckyao.studyspec.view import resolve_study

from studies import REPO, TINY, snakemake, tiny, with_name, with_sweep

LIST_BOMB = "a0: &a0 [1, 2]\n" + "".join(f"a{i}: &a{i} [*a{i - 1}, *a{i - 1}]\n" for i in range(1, 30))
MAPPING_BOMB = "d0: &d0 {x: 1}\n" + "".join(f"d{i}: &d{i} {{p: *d{i - 1}, q: *d{i - 1}}}\n" for i in range(1, 30))


def check(capsys, *paths) -> tuple[int, str]:
    code = main(["check", *map(str, paths)])
    captured = capsys.readouterr()
    return code, captured.out + captured.err


# --- detector names (item 3) ---------------------------------------------------------------


def test_a_detector_named_like_a_sweep_detector_is_refused_by_key():
    """The tiny study's sweep names rn0.1_100ph: a listed detector of that name would be
    replaced by the sweep's in the cases that get the sweep, a figure comparing two detectors
    under one name."""
    study = tiny()
    assert "rn0.1_100ph" in sweep_detectors(study["lucky"])
    study["lucky"]["detectors"]["rn0.1_100ph"] = {"photons_per_frame": 50, "read_noise_e": 3.0}
    with pytest.raises(ConfigError, match=r"config key 'lucky\.detectors\.rn0\.1_100ph': the detector sweep names"):
        validate_study(study)


def test_sweep_detectors_that_would_share_a_name_are_refused_by_key():
    study = tiny()
    study["lucky"]["detector_sweep"]["photons_per_frame"] = {"min": 100, "max": 100.1, "levels": 3}  # all 100ph
    with pytest.raises(
        ConfigError,
        match=r"config key 'lucky\.detector_sweep\.photons_per_frame': .*share the name "
        r"'rn0\.1_100ph'",
    ):
        validate_study(study)
    study = tiny()
    study["lucky"]["detector_sweep"]["read_noise_e"] = [0.1, 0.1000001]  # rn0.1 both
    with pytest.raises(ConfigError, match=r"config key 'lucky\.detector_sweep\.read_noise_e'"):
        validate_study(study)


def test_a_detector_sweep_is_bounded():
    study = tiny()
    study["lucky"]["detector_sweep"]["photons_per_frame"]["levels"] = 10**8
    start = time.perf_counter()
    with pytest.raises(ConfigError, match=r"config key 'lucky\.detector_sweep': .*100,000,000 detectors"):
        validate_study(study)
    assert time.perf_counter() - start < 5


# --- names (items 8, 10) -------------------------------------------------------------------


@pytest.mark.parametrize("name", ["good\n", "x\n", "caf\u00e9", "g\u00f6\u00f6d", "tab\t", "a" * 129, "a" * 300])
@pytest.mark.parametrize("kind", ["case", "figure", "detector"])
def test_a_name_is_matched_whole_short_and_ascii(kind, name):
    """'good\\n' passed `$` (it matches before a final newline) and made folders with a newline
    in their names; 300 characters failed mid-run (a file name holds 255 bytes)."""
    study, key = with_name(kind, name)
    with pytest.raises(
        ConfigError,
        match=rf"config key '{key}': .*(is not a safe name|characters long, more than "
        r"the 128)",
    ):
        validate_study(study)


def test_the_longest_name_allowed_runs_its_file_names():
    study = tiny()
    study["cases"]["a" * 128] = {}
    validate_study(study)


@pytest.mark.parametrize("where", ["sweep", "parameter"])
def test_sweep_and_parameter_names_are_matched_whole(where):
    study = with_sweep({"atmosphere.r0_500nm_m": [0.3]})
    if where == "sweep":
        study["sweeps"]["grid\n"] = study["sweeps"].pop("grid")
        study["figures"]["grid"]["sweep"] = "grid\n"
    else:
        study["sweeps"]["grid"]["parameters"] = {"atmosphere.r0_500nm_m\n": [0.3]}
    with pytest.raises(ConfigError, match=r"config key 'sweeps"):
        validate_study(study)


def test_a_sweep_point_named_longer_than_a_file_name_allows_is_refused_by_key():
    study = with_sweep({"lgs.profile": ["range_gate" + "x" * 130]})
    with pytest.raises(ConfigError, match=r"config key 'sweeps\.grid\.parameters': the grid point .* characters long"):
        validate_study(study)


# --- near-equal sweep values (item 11) ----------------------------------------------------------


def test_sweep_values_that_would_share_a_name_are_refused_by_key():
    """Names keep 6 significant digits: 0.121 and 0.1210001 were one case, drawn at two x."""
    study = with_sweep({"atmosphere.r0_500nm_m": [0.121, 0.1210001, 0.3]})
    with pytest.raises(
        ConfigError,
        match=r"config key 'sweeps\.grid\.parameters\.atmosphere\.r0_500nm_m': the values "
        r"0\.121 and 0\.1210001 would share the case name 'grid_r0_500nm_m-0\.121'",
    ):
        validate_study(study)
    validate_study(with_sweep({"atmosphere.r0_500nm_m": [0.121, 0.1211, 0.3]}))  # six digits apart: two cases


# --- seeds, labels (item 10) -----------------------------------------------------------------


def test_a_seed_outside_0_to_2_63_is_refused_by_key():
    study = tiny()
    study["seed"] = 2**63 - 1
    validate_study(study)
    for seed in (2**63, 2**64 + 5, -1):
        study["seed"] = seed
        with pytest.raises(ConfigError, match=r"config key 'seed'"):
            validate_study(study)


@pytest.mark.parametrize(
    "label, drawable",
    [
        (r"turned asterism", True),
        (r"$\alpha$ - $r_0$ (50%)", True),
        (r"costs $5", True),
        (r"$\undefinedmacro$ - b", False),
        (r"a $x^$ b", False),
    ],
)
def test_a_label_matplotlib_cannot_draw_is_refused_by_key(label, drawable):
    """A label with an undefined macro killed the figure job after every simulation."""
    study = tiny()
    study["figures"]["paired"]["pairs"][0]["label"] = label
    if drawable:
        validate_study(study)
    else:
        with pytest.raises(
            ConfigError,
            match=r"config key 'figures\.paired\.pairs\[0\]\.label': matplotlib cannot "
            r"draw",
        ):
            validate_study(study)


def test_two_pairs_of_one_label_are_refused_by_key():
    study = tiny()
    pairs = study["figures"]["paired"]["pairs"]
    pairs.append(dict(pairs[0], a=pairs[0]["b"], b=pairs[0]["a"]))
    with pytest.raises(ConfigError, match=r"config key 'figures\.paired\.pairs\[1\]\.label'"):
        validate_study(study)


# --- strict YAML, bounded grids (items 9, 10) ------------------------------------------------


@pytest.mark.parametrize(
    "overlay, message",
    [
        ("seed: 1\nseed: 2\n", r"key 'seed' is written twice in one mapping \(lines 1 and 2\)"),
        ("lucky:\n  fractions: [0.1]\n  fractions: [0.5]\n", r"key 'fractions' is written twice .*lines 2 and 3"),
        ("- seed\n- 1\n", r"its top level is a list, not a mapping"),
        ("7\n", r"its top level is a int, not a mapping"),
        ("x: &x [*x]\n", r"a YAML alias refers to a value that holds it"),
        (LIST_BOMB, r"holds more than 100,000 values once its YAML aliases"),
        (MAPPING_BOMB, r"holds more than 100,000 values once its YAML aliases"),
    ],
    ids=["duplicate", "nested-duplicate", "list", "number", "recursive-alias", "list-bomb", "mapping-bomb"],
)
def test_check_refuses_a_config_file_naming_it(overlay, message, tmp_path, capsys):
    path = tmp_path / "overlay.yaml"
    path.write_text(overlay)
    start = time.perf_counter()
    code, output = check(capsys, TINY, path)
    assert code == 1 and f"config file '{path}'" in output, output
    assert len(output.strip().splitlines()) == 1 and __import__("re").search(message, output), output
    assert time.perf_counter() - start < 10


def test_yaml_merge_keys_and_the_studies_still_read():
    from luckyao.studyspec.yamlfile import read_config_text

    assert read_config_text("b: &b {x: 1, y: 2}\nc: {<<: *b, x: 3}\n", "t") == {
        "b": {"x": 1, "y": 2},
        "c": {"x": 3, "y": 2},
    }
    for path in [TINY, *sorted((REPO / "config").glob("*.yaml"))]:
        assert read_config_text(path.read_text(), str(path)) == yaml.safe_load(path.read_text())


def test_a_grid_too_large_is_refused_at_once_by_key():
    """A grid of 10^6 points hung `check` for more than 10 minutes; 10^4 planned 40,202 jobs."""
    values = [0.1 + 0.001 * i for i in range(100)]
    for parameters, points in (
        ({"atmosphere.r0_500nm_m": values, "atmosphere.outer_scale_m": values[:20]}, "2,000"),
        (
            {"atmosphere.r0_500nm_m": values, "atmosphere.outer_scale_m": values, "camera.wavelength_m": values},
            "1,000,000",
        ),
    ):
        start = time.perf_counter()
        with pytest.raises(
            ConfigError,
            match=rf"config key 'sweeps\.grid\.parameters': a grid of {points} points "
            r"\(100 x .* values.*\), more than the 1,000 a study may hold",
        ):
            validate_study(with_sweep(parameters))
        assert time.perf_counter() - start < 5


@pytest.mark.workflow
@pytest.mark.parametrize("bomb", [LIST_BOMB, MAPPING_BOMB], ids=["list-bomb", "mapping-bomb"])
def test_the_workflow_refuses_an_alias_bomb_before_reading_it(bomb, tmp_path):
    """A 2 KB alias bomb hung the dry run (Snakemake's own config merge, or the checks)."""
    folder = tmp_path / "study"
    (folder / "config").mkdir(parents=True)
    (folder / "config" / "config.yaml").write_text(
        TINY.read_text() + "junk:\n" + "".join(f"  {line}\n" for line in bomb.splitlines())
    )
    result = snakemake(folder, "-n", cores=1, timeout=120)
    assert result.returncode != 0
    assert (
        "luckyao: invalid study config: config file 'config/config.yaml': holds more than 100,000 values"
        in result.stderr
    ), result.stderr[-2000:]


@pytest.mark.workflow
def test_run_sh_refuses_an_overlay_alias_bomb_before_snakemake_merges_it(tmp_path):
    """Snakemake merges --configfile overlays itself, walking every path of a mapping bomb:
    `bash run.sh study` (luckyao.jobs.live_run) reads them strictly first."""
    folder = tmp_path / "study"
    (folder / "config").mkdir(parents=True)
    (folder / "config" / "config.yaml").write_text(TINY.read_text())
    overlay = tmp_path / "bomb.yaml"
    overlay.write_text("junk:\n" + "".join(f"  {line}\n" for line in MAPPING_BOMB.splitlines()))
    result = snakemake(folder, "-n", "--configfile", str(overlay), cores=1, module="luckyao.jobs.live_run", timeout=120)
    assert result.returncode != 0
    assert f"config file '{overlay}': holds more than 100,000 values" in result.stderr, result.stderr[-2000:]


# --- one pre-flight, sizes (item 9) ---------------------------------------------------------------


def huge(tmp_path) -> Path:
    """duration_s 1e7: about 3 TB of memory for each simulation, the issue's 12,870 GB case."""
    path = tmp_path / "huge.yaml"
    path.write_text("turbulence: {duration_s: 1.0e+7}\nbase: {duration_s: 1.0e+7}\n")
    return path


def test_check_refuses_a_study_too_large_for_this_machine(tmp_path, capsys):
    """`luckyao check` called it valid while the dry run refused it: one pre-flight now."""
    code, output = check(capsys, TINY, huge(tmp_path))
    assert code == 1 and "valid, " not in output, output
    assert "study too large: config key 'turbulence': job turbulence screens_" in output, output
    assert "study too large: config key 'cases.ltao': job simulate ltao needs about 3,2" in output, output
    code, output = check(capsys, TINY)
    assert code == 0 and "valid, 8 cases" in output


@pytest.mark.workflow
def test_the_dry_run_refuses_what_check_refuses(tmp_path):
    folder = tmp_path / "study"
    (folder / "config").mkdir(parents=True)
    (folder / "config" / "config.yaml").write_text(TINY.read_text())
    result = snakemake(folder, "-n", "--configfile", str(huge(tmp_path)), cores=1, timeout=300)
    assert result.returncode != 0
    assert "luckyao: study too large: config key 'cases.ltao': job simulate ltao needs" in result.stderr, result.stderr[
        -2000:
    ]


def free_disk(monkeypatch, free_bytes: float) -> None:
    monkeypatch.setattr(resources.shutil, "disk_usage", lambda folder: type("U", (), {"free": free_bytes})())


def test_the_files_of_a_study_are_summed_against_the_free_disk(tmp_path, monkeypatch):
    """With keep_frames every frame cube stays: the sum must fit, not each file alone (the
    paper run with keep_frames, ~130 GB, was accepted with 40 GB free)."""
    study = expand_study(dict(tiny(), keep_frames=True))
    cases = validate_study(study)
    sizes = [job.output_bytes for job in study_jobs(resolve_study(study, cases)) if job.output is not None]
    free_disk(monkeypatch, max(sizes) * 1.01)
    assert sum(sizes) > max(sizes) * 1.01
    problems = preflight(resolve_study(study, cases), tmp_path, memory_bytes=1e15)
    assert len(problems) == 1 and problems[0].startswith(
        "config key 'keep_frames': the study's files not yet made need about"
    ), problems
    assert "every frame cube kept" in problems[0]
    free_disk(monkeypatch, sum(sizes) * 1.01)
    assert preflight(resolve_study(study, cases), tmp_path, memory_bytes=1e15) == []


def test_frame_cubes_deleted_once_post_processed_count_as_many_as_run_at_once(tmp_path, monkeypatch):
    study = expand_study(tiny())
    cases = validate_study(study)
    jobs = [(job.name, job.output_bytes) for job in study_jobs(resolve_study(study, cases)) if job.output is not None]
    lasting = sum(size for job, size in jobs if not job.startswith("simulate "))
    frames = sorted((size for job, size in jobs if job.startswith("simulate ")), reverse=True)
    free_disk(monkeypatch, lasting + frames[0] + frames[1] / 2)
    assert preflight(resolve_study(study, cases), tmp_path, memory_bytes=1e15, parallel_jobs=1) == []
    problems = preflight(resolve_study(study, cases), tmp_path, memory_bytes=1e15, parallel_jobs=2)
    assert len(problems) == 1 and "the 2 largest frame cubes at once" in problems[0]


def test_a_file_already_made_needs_no_disk(tmp_path, monkeypatch):
    study = expand_study(dict(tiny(), keep_frames=True))
    cases = validate_study(study)
    for output in (job.output for job in study_jobs(resolve_study(study, cases))):
        if output is not None:
            (tmp_path / output).parent.mkdir(parents=True, exist_ok=True)
            (tmp_path / output).touch()
    free_disk(monkeypatch, 0.0)
    assert preflight(resolve_study(study, cases), tmp_path, memory_bytes=1e15) == []


# --- draw and export say what they expected (item 10) ---------------------------------------------


def titled(path: Path, title: str, **variables) -> Path:
    xr.Dataset(
        {name: ("x", np.asarray(values, dtype=float)) for name, values in variables.items()},
        attrs={"title": title, "config_json": json.dumps({"duration_s": 1.0})},
    ).to_netcdf(path)
    return path


def test_draw_says_it_expected_a_figures_data():
    import luckyao

    case = xr.Dataset(
        {"strehl": ("x", [0.1])},
        attrs={"title": "luckyao lucky imaging of case good", "config_json": json.dumps({"duration_s": 1.0})},
    )
    with pytest.raises(
        ValueError,
        match=r"luckyao\.draw: expected a figure's data \(figures/<id>\.nc\), got a "
        r"case's lucky-imaging results",
    ):
        luckyao.draw(case)


def test_export_says_it_expected_a_cases_lucky_results(tmp_path, capsys):
    path = titled(tmp_path / "telemetry.nc", "luckyao telemetry of case good", frame_strehl=[0.1, 0.2])
    code = main(["export", str(path), "--out", str(tmp_path / "x.fits")])
    output = capsys.readouterr().err
    assert (
        code == 1
        and "expected a case's lucky-imaging results (results/cases/<case>/lucky.nc), got a case's telemetry" in output
    ), output
    assert "n_pixels" not in output and not (tmp_path / "x.fits").exists()


def test_without_frame_cubes_a_study_needs_only_its_telemetry_on_disk():
    """``replay_frames``: no simulation job writes a cube; its file is the telemetry, far
    smaller (the DM commands and a few values per frame)."""
    cubes = expand_study(tiny())
    replayed = dict(cubes, replay_frames=True)
    cases = validate_study(cubes)
    sizes = {
        name: {
            job.name: (job.output, job.output_bytes)
            for job in study_jobs(resolve_study(study, cases))
            if job.name.startswith("sim")
        }
        for name, study in (("cubes", cubes), ("replayed", replayed))
    }
    for job, (output, size) in sizes["replayed"].items():
        assert output.endswith("/telemetry.nc") and size < sizes["cubes"][job][1] / 5, job
        assert sizes["cubes"][job][0].endswith("/frames.nc")


@pytest.mark.parametrize("what", ["keep_frames", "apodisation"])
def test_replaying_frames_refuses_a_kept_cube_and_an_apodised_case_by_key(what):
    study = dict(tiny(), replay_frames=True)
    if what == "keep_frames":
        study["keep_frames"], key = True, "config key 'replay_frames'"
    else:
        study["cases"]["ltao"]["ao"]["apodisation"] = {"driver": "lgs", "blocked_fraction": 0.1}
        key = "config key 'cases.ltao.ao.apodisation': an adaptively apodised case cannot be replayed"
    with pytest.raises(ConfigError, match=key):
        validate_study(expand_study(study))


def test_wall_times_grow_with_the_telescope_and_the_passes_of_a_replay():
    """SLURM wall times: a stored cube's lucky job keeps the measured 30 minutes; replaying a
    16 m case of 100 s (40,000 steps) redoes its science path once per pass, 3 with noise."""
    from luckyao.jobs.resources import lucky_minutes, simulate_minutes

    study = dict(tiny(), replay_frames=True)
    study["turbulence"].pop("duration_s")  # each case's screens as long as it needs
    study["cases"]["big"] = {"duration_s": 100.0, "telescope": {"diameter_m": 16.0, "obscuration_m": 4.571}}
    cases = validate_study(expand_study(study))
    view = resolve_study(expand_study(study), cases)
    settings = view.cases["big"].lucky_settings
    assert simulate_minutes(cases["good"]) == 60 and simulate_minutes(cases["big"]) > 60
    noiseless = dict(settings, detectors={"noiseless": {"photons_per_frame": None, "read_noise_e": 0.0}})
    assert 30 < lucky_minutes(noiseless) < lucky_minutes(dict(settings, detectors={"f": {"photons_per_frame": 10}}))
    assert lucky_minutes({k: v for k, v in settings.items() if k != "replay_frames"}) == 30


def _paper_view():
    paper, cases = load_study(REPO / "config" / "config.yaml", REPO / "config" / "paper.yaml")
    return resolve_study(expand_study(paper), cases)


def test_time_estimates_meet_the_paper_runs_measurements():
    """The estimates against the paper run's measured jobs (docs/performance.md): the sweep
    case with all four registration methods 19.7 min alone on one core and, a measurement
    none of the constants rests on, 14.1 min with cog and xcorr only; a case with the noiseless
    detector alone 22.8 s; the screens 2.8 min on two threads; at most 10 % apart."""
    view = _paper_view()
    sweep = view.cases["ltao_r0_13.5cm"].lucky_settings
    assert resources.lucky_seconds(sweep) == pytest.approx(19.7 * 60, rel=0.1)
    assert resources.lucky_seconds(dict(sweep, registration=["cog", "xcorr"])) == pytest.approx(14.1 * 60, rel=0.1)
    assert resources.lucky_seconds(view.cases["glao_r0_13.5cm"].lucky_settings) == pytest.approx(22.8, rel=0.1)
    assert resources.screens_seconds(view.cases["glao_r0_13.5cm"].screens.spec) == pytest.approx(2.8 * 60, rel=0.1)


def test_wall_times_are_the_margin_over_the_estimates():
    """Each declared wall time is RUNTIME_MARGIN x the plain estimate (one formula each), at
    least the floor: the paper's sweep case 3 x its 19.7 minutes, above the former flat 30."""
    view = _paper_view()
    for name in ("ltao_r0_13.5cm", "ltao_field", "noao_r0_20cm"):
        case = view.cases[name]
        seconds = resources.lucky_seconds(case.lucky_settings)
        assert resources.lucky_minutes(case.lucky_settings) == max(30, -(-3 * seconds // 60))
        seconds = resources.simulate_seconds(case.config)
        assert resources.simulate_minutes(case.config) == max(60, -(-3 * seconds // 60))
    assert resources.lucky_minutes(view.cases["ltao_r0_13.5cm"].lucky_settings) > 55


def test_every_job_has_a_time_estimate():
    jobs = study_jobs(_paper_view())
    steps = {job.name.split()[0] for job in jobs}
    assert steps == {"turbulence", "calibration", "reconstructor", "commands", "slopes", "simulate", "lucky"}
    assert all(job.seconds > 0 for job in jobs)


@pytest.mark.parametrize("noisy", [False, True])
def test_the_declared_partial_sums_are_those_a_lucky_run_allocates(noisy):
    """``resources.partial_sums_bytes`` against the arrays :class:`.lucky.accumulation.PartialSums`
    allocates for the same run (``cog``; a sub-pixel method's vector: test_registration.py): the
    run's, the long exposure's and the time blocks' rows, with a noisy detector the image
    criteria's rows for every block (the detector sweep's case ``lgs``)."""
    from luckyao.lucky.accumulation import PartialSums, TimeBlocks
    from luckyao.lucky.ranking import fraction_counts
    from luckyao.studyspec.resolved import criteria_of

    study = tiny()
    study["lucky"]["registration"] = ["cog"]
    if not noisy:
        study["lucky"]["detectors"]["faint"] = {"photons_per_frame": None, "read_noise_e": 0.0}
    study = expand_study(study)
    settings = resolve_study(study, validate_study(study)).cases["lgs" if noisy else "ltao"].lucky_settings
    config = settings["case_config"]
    n_frames, n_blocks = resources.frame_count(config), settings["error_blocks"]
    n_det, n_crit = len(settings["detectors"]), len(criteria_of(config))
    assert n_blocks >= 2 and any(d["photons_per_frame"] is not None for d in settings["detectors"].values()) == noisy
    blocks = TimeBlocks(n_frames, n_blocks, settings["fractions"], n_det, n_crit)
    sums = PartialSums(n_det, n_crit, fraction_counts(n_frames, settings["fractions"]), blocks, [0, 1] if noisy else [])
    n = config["camera"]["n_pixels"]
    sums.allocate((n, n), resources.FRAME_BLOCK)
    assert resources.partial_sums_bytes(settings) == sums.detected_rows.nbytes + sums.noiseless_rows.nbytes
