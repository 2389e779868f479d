"""Command-line interface: one subcommand per workflow step.

luckyao check CONFIG [OVERLAY ...] [case=NAME] [key.path=value ...] [--study-dir DIR] [--mem-mb N]
luckyao show CASE [key.path=value ...] [--configfile OVERLAY ...] [--json]
luckyao turbulence --spec JSON --screens S.npy --metadata S.nc
luckyao simulate --case JSON --name NAME --seed N --screens S.npy --screens-metadata S.nc
                 [--reconstructor R.nc] [--commands C.nc] [--calibration W.nc] [--lgs-telemetry T.nc]
                 --frames F --telemetry T
luckyao reconstructor --spec JSON --out R.nc
luckyao calibration --spec JSON --out W.nc
luckyao commands --spec JSON --out C.nc
luckyao lucky --settings JSON --frames F --telemetry T --out lucky.nc [--screens S.npy --screens-metadata S.nc]
luckyao figure --id ID (--settings JSON | --settings-file S.json) --out-prefix figures/ID  lucky.nc ...
luckyao export lucky.nc --out images.fits [--detector NAME ...] [--registration NAME ...] [--cube]
luckyao table figures/longexp.nc
luckyao knees figures/registration.nc [--fraction F] [--criterion C] [--read-noise R]
luckyao archive [--study-dir DIR] [--configfile OVERLAY ...] [--out A.tar]
luckyao verify A.tar [--case NAME | --all-cases] [--workdir DIR] [--rtol R] [--atol A] [--no-rerun]
luckyao lock [--out FILE]
"""

import argparse
import json
import logging
import os
import signal
import sys
import time


def _setup_logging() -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s", stream=sys.stderr)


def cmd_check(args) -> int:
    """One line: valid, or one line per problem naming its key (no traceback): the workflow's
    own pre-flight (``jobs.resources.checked_study``), so what its dry run refuses is refused
    here, for the study folder ``--study-dir``."""
    from .jobs.resources import StudyTooLarge, checked_study, machine_memory_bytes
    from .studyspec.overrides import is_override, split_words
    from .studyspec.schema import ConfigError
    from .studyspec.study import plausibility_warnings

    paths = [word for word in args.config if not is_override(word)]
    case, overrides, _ = split_words([word for word in args.config if is_override(word)])
    files = " + ".join(paths + overrides + ([f"case={case}"] if case else []))
    memory = max(machine_memory_bytes(), 1e6 * (args.mem_mb or 0))
    try:
        view = checked_study(_study_with(paths, overrides, case), args.study_dir, memory)
    except ConfigError as err:
        what = "study too large" if isinstance(err, StudyTooLarge) else "invalid"
        for problem in str(err).splitlines():
            print(f"{files}: {what}: {problem}", file=sys.stderr)
        return 1
    for warning in plausibility_warnings(view.configs):
        print(f"{files}: warning: {warning}", file=sys.stderr)
    if view.unused:
        print(f"{files}: warning: no figure shows the cases {', '.join(view.unused)}", file=sys.stderr)
    print(f"{files}: valid, {len(view.cases)} cases")
    return 0


def _study_with(paths: list[str], overrides: list[str], case: str | None) -> dict:
    """The study of config files merged in order, with ``key=value`` overrides (``studyspec.overrides``)."""
    from .studyspec.overrides import parse_overrides
    from .studyspec.schema import deep_merge
    from .studyspec.study import read_study

    config = read_study(*paths)
    return deep_merge(config, parse_overrides(overrides, case)) if overrides or case else config


def cmd_show(args) -> int:
    """The fully resolved case: every key, what was derived, the products, the estimates."""
    from .jobs.resources import StudyTooLarge, checked_study, machine_memory_bytes
    from .jobs.show import case_report, case_text
    from .studyspec.schema import ConfigError

    paths = ["config/config.yaml", *args.configfile]
    try:
        view = checked_study(_study_with(paths, args.overrides, args.case), args.study_dir, machine_memory_bytes())
    except StudyTooLarge as err:
        print(f"luckyao show: warning: {err}", file=sys.stderr)
        from .studyspec.study import validate_study
        from .studyspec.sweeps import expand_study
        from .studyspec.view import resolve_study

        study = expand_study(_study_with(paths, args.overrides, args.case))
        view = resolve_study(study, validate_study(study))
    except ConfigError as err:
        for problem in str(err).splitlines():
            print(f"luckyao show: invalid: {problem}", file=sys.stderr)
        return 1
    report = case_report(view, args.case)
    print(json.dumps(report, indent=1) if args.json else case_text(report))
    return 0


def cmd_turbulence(args) -> None:
    from .io.datasets import provenance
    from .steps.screens import write_screens

    spec = json.loads(args.spec)
    write_screens(
        spec,
        args.screens,
        args.metadata,
        provenance("luckyao normalised phase screens", spec, spec["seed"]),
        threads=args.threads,
    )


def cmd_simulate(args) -> None:
    from .io.datasets import FrameWriter, open_dataset, provenance, write_dataset
    from .steps.lgs_slopes import RecordedSlopes
    from .steps.screens import read_screens
    from .steps.simulation import TimeLoop, twin_lgs_rms_nm
    from .studyspec.case import Case
    from .studyspec.resolved import imaged_targets

    config = json.loads(args.case)
    case = Case.from_config(config)
    screens = read_screens(args.screens, args.screens_metadata)
    reconstructors = (
        open_dataset(args.reconstructor, "reconstructor", allow_nan=())["reconstructor"].values
        if args.reconstructor
        else None
    )
    # an AO case: its LGS slopes measured by their product job
    slopes = RecordedSlopes.open(args.slopes, config, args.seed) if args.slopes else None
    calibration = open_dataset(args.calibration, "WFS calibration", allow_nan=()) if args.calibration else None
    lgs_rms_nm = twin_lgs_rms_nm(args.lgs_telemetry, config, args.seed) if args.lgs_telemetry else None
    commands = None
    if args.commands:
        products = open_dataset(args.commands, "AO command", allow_nan=())
        commands = products["command_matrix"].values, products["dm_slopes"].values
    attrs = provenance(f"luckyao frames of case {args.name}", config, args.seed)
    # without a frames file (replay_frames) no target is imaged: the lucky job makes the frames again
    imaged = imaged_targets(config) if args.frames else []
    loop = TimeLoop(
        case,
        screens,
        args.seed,
        reconstructors=reconstructors,
        calibration=calibration,
        slopes=slopes,
        commands=commands,
        lgs_rms_nm=lgs_rms_nm,
        imaged_targets=imaged,
    )
    start = time.perf_counter()
    if args.frames:
        with FrameWriter(
            args.frames, imaged, case.n_frames, case.camera.n_pixels, case.camera.pixel_scale_arcsec, attrs
        ) as writer:
            telemetry = loop.run(writer.write)
    else:
        telemetry = loop.run(lambda start, frames: None)
    elapsed = time.perf_counter() - start
    steps = case.clock.n_steps
    logging.getLogger(__name__).info(
        "simulated %d steps in %.1f s: %.3f ms per step (with I/O)", steps, elapsed, 1e3 * elapsed / steps
    )
    telemetry.attrs.update(provenance(f"luckyao telemetry of case {args.name}", config, args.seed))
    telemetry.attrs["case"] = args.name
    write_dataset(telemetry, args.telemetry, allow_nan={"axis_strehl"} if len(imaged) < len(case.targets) else ())


def cmd_slopes(args) -> None:
    from .io.datasets import open_dataset, provenance, write_dataset
    from .steps.lgs_slopes import measure_lgs_slopes
    from .steps.screens import read_screens

    spec = json.loads(args.spec)
    calibration = open_dataset(args.calibration, "WFS calibration", allow_nan=()) if args.calibration else None
    ds = measure_lgs_slopes(spec, read_screens(args.screens, args.screens_metadata), calibration)
    ds.attrs.update(provenance("luckyao LGS slopes", spec, spec["seed"]))
    write_dataset(ds, args.out, compress=False)


def cmd_reconstructor(args) -> None:
    from .io.datasets import provenance, write_dataset
    from .steps.reconstructor import build_reconstructors

    spec = json.loads(args.spec)
    ds = build_reconstructors(spec)
    ds.attrs.update(provenance("luckyao tomographic reconstructors", spec, 0))
    write_dataset(ds, args.out, compress=False)


def cmd_commands(args) -> None:
    from .io.datasets import provenance, write_dataset
    from .steps.reconstructor import build_commands

    spec = json.loads(args.spec)
    ds = build_commands(spec)
    ds.attrs.update(provenance("luckyao AO command matrix", spec, 0))
    write_dataset(ds, args.out, compress=False)


def cmd_calibration(args) -> None:
    from .io.datasets import provenance, write_dataset
    from .steps.calibration import build_calibration

    spec = json.loads(args.spec)
    ds = build_calibration(spec)
    ds.attrs.update(provenance("luckyao WFS slope-response calibration", spec, spec["seed"]))
    write_dataset(ds, args.out, compress=False)


def cmd_lucky(args) -> None:
    from .steps.postprocess import lucky_case

    lucky_case(
        json.loads(args.settings),
        args.frames,
        args.telemetry,
        args.out,
        args.screens,
        args.screens_metadata,
        args.learned_model,
    )


def cmd_learn(args) -> None:
    from .io.datasets import open_dataset, write_dataset
    from .steps.learned import train_model

    telemetry = open_dataset(args.telemetry, "training telemetry", allow_nan={"axis_strehl"})
    write_dataset(train_model(telemetry), args.out, compress=False)


def cmd_figure(args) -> None:
    from .figures import draw_figure

    if args.settings_file:
        with open(args.settings_file) as f:
            settings = json.load(f)
    else:
        settings = json.loads(args.settings)
    draw_figure(args.id, settings, args.inputs, args.out_prefix)


def cmd_export(args) -> None:
    from .io.fits import export_fits

    n = export_fits(args.lucky, args.out, args.detector, args.registration, "cube" if args.cube else "images")
    logging.getLogger(__name__).info("wrote %s: %d images", args.out, n)


def cmd_table(args) -> None:
    from .figures import long_exposure_markdown
    from .io.datasets import open_dataset

    data = open_dataset(args.data, "long_exposure_table figure data", remake=False)
    if "best_lucky_strehl" not in data:
        raise ValueError(
            f"'{args.data}' is not a long_exposure_table figure's data (it has no best_lucky_strehl); "
            "give one such as figures/longexp.nc"
        )
    sys.stdout.write(long_exposure_markdown(data))


def cmd_knees(args) -> None:
    from .figures.registration import knee_markdown
    from .io.datasets import open_dataset

    data = open_dataset(args.data, "registration figure data", remake=False)
    if "strehl_knee_photons" not in data:
        raise ValueError(
            f"'{args.data}' is not a registration figure's data (it has no strehl_knee_photons); "
            "give one such as figures/registration.nc"
        )
    fraction = float(data.fraction.values[0]) if args.fraction is None else args.fraction
    for key, value, coord in (
        ("--fraction", fraction, "fraction"),
        ("--criterion", args.criterion, "criterion"),
        ("--read-noise", args.read_noise, "read_noise"),
    ):
        if value not in data[coord].values:
            raise ValueError(f"{key} {value}: '{args.data}' has {list(data[coord].values)}")
    band = data.attrs.get("photometric_band", "I")
    sys.stdout.write(
        f"Knees at {100 * fraction:g} % of frames, selection by {args.criterion}, read noise "
        f"{args.read_noise:g} e-: the signal from which the integrated Strehl keeps 90 % of its "
        f"noiseless value and d50 stays within 10 % of it ({band} magnitude: "
        f"{float(data.attrs['i_zero_photons_per_frame']):.3g} photons per frame at {band} = 0, "
        "the figure's photometric scale)\n\n"
    )
    sys.stdout.write(knee_markdown(data, fraction, args.criterion, args.read_noise) + "\n")


def cmd_archive(args) -> int:
    """One tar file of a finished study; problems one line each (no traceback)."""
    from .archive.create import archive

    try:
        archive(args.study_dir, args.configfile, args.out)
    except ValueError as err:  # ConfigError, ArchiveError
        for problem in str(err).splitlines():
            print(f"luckyao archive: {problem}", file=sys.stderr)
        return 1
    return 0


def cmd_verify(args) -> int:
    """0 when the archive's checksums and the rerun case agree, else 1 naming what differs."""
    from .archive.verify import verify

    try:
        agrees = verify(
            args.archive,
            args.case,
            args.workdir,
            args.rtol,
            args.atol,
            args.cores,
            args.snakefile,
            rerun=not args.no_rerun,
            all_cases=args.all_cases,
        )
    except ValueError as err:
        print(f"luckyao verify: FAILED: {err}", file=sys.stderr)
        return 1
    return 0 if agrees else 1


def cmd_lock(args) -> None:
    from .archive.create import requirements_lock

    text = requirements_lock()
    if args.out:
        with open(args.out, "w") as f:
            f.write(text)
    else:
        sys.stdout.write(text)


def main(argv=None) -> int:
    """Run one subcommand; a failure is one line naming the file or key (no traceback;
    ``LUCKYAO_TRACEBACK=1`` shows it)."""
    from .jobs.live_run import hold_job_lock
    from .threads import is_study_job

    if is_study_job():  # a job of the workflow holds its study's run lock while it lives, first of all
        hold_job_lock()
    args = build_parser().parse_args(argv)
    _setup_logging()
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a file over the size limit: a named write error, not a kill
    try:
        return args.func(args) or 0
    except (ValueError, OSError, KeyError, RuntimeError) as err:
        if os.environ.get("LUCKYAO_TRACEBACK"):
            raise
        message = f"missing {err}" if isinstance(err, KeyError) else str(err)
        detail = f" ({type(err).__name__})" if isinstance(err, (OSError, KeyError)) else ""
        print(f"luckyao {args.command}: error{detail}: {message}", file=sys.stderr)
        return 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="luckyao", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser(
        "check",
        help="validate a study config (later files are merged over earlier ones) and check "
        "that its jobs fit this machine, as the workflow does before any job",
    )
    p.add_argument(
        "config",
        nargs="+",
        help="config files (later merged over earlier), then case=NAME and key.path=value overrides",
    )
    p.add_argument("--study-dir", default=".", help="the study folder whose free disk is checked (default: here)")
    p.add_argument(
        "--mem-mb",
        type=int,
        help="memory of the machine the jobs run on [MB], if larger than this one's "
        "(as Snakemake's --resources mem_mb=N)",
    )
    p.set_defaults(func=cmd_check)

    p = sub.add_parser(
        "show",
        help="print a case fully resolved: every key (the derived ones named), the tomography prior, "
        "the screens, the products and the jobs' estimated time, memory and disk",
    )
    p.add_argument("case", help="a case of the study, or a new one (an override of base)")
    p.add_argument("overrides", nargs="*", help="key.path=value overrides (a case's key: of this case)")
    p.add_argument("--configfile", nargs="+", default=[], help="overlays merged over config/config.yaml")
    p.add_argument("--study-dir", default=".", help="the study folder whose free disk is checked (default: here)")
    p.add_argument("--json", action="store_true", help="JSON for machines instead of text")
    p.set_defaults(func=cmd_show)

    p = sub.add_parser("turbulence", help="generate the shared normalised phase screens")
    p.add_argument("--spec", required=True, help="turbulence spec as JSON")
    p.add_argument("--screens", required=True, help="flat .npy of the screens")
    p.add_argument("--metadata", required=True, help="netCDF description of the screens")
    p.add_argument("--threads", type=int, default=1, help="layers made at once (the same numbers for any)")
    p.set_defaults(func=cmd_turbulence)

    p = sub.add_parser("simulate", help="run one case's time loop")
    p.add_argument("--case", required=True, help="resolved case config as JSON")
    p.add_argument("--name", required=True)
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--screens", required=True)
    p.add_argument("--screens-metadata", required=True)
    p.add_argument("--reconstructor", default="", help="reconstructor file (cases with LGS)")
    p.add_argument("--commands", default="", help="AO command-matrix file (cases with AO)")
    p.add_argument("--calibration", default="", help="WFS calibration file (cases with wfs.calibration)")
    p.add_argument(
        "--lgs-telemetry",
        default="",
        help="telemetry of the AO case that measured this no-AO case's LGS rms (studyspec.products.lgs_twin)",
    )
    p.add_argument("--slopes", default="", help="LGS slopes product (cases with AO, config.slopes_spec)")
    p.add_argument("--frames", default="", help="frame cube to write (none: no target imaged, replay_frames)")
    p.add_argument("--telemetry", required=True)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("slopes", help="measure the LGS slopes of an AO case's LGS chain")
    p.add_argument("--spec", required=True, help="slopes spec as JSON (config.slopes_spec)")
    p.add_argument("--screens", required=True)
    p.add_argument("--screens-metadata", required=True)
    p.add_argument("--calibration", default="", help="WFS calibration file (cases with wfs.calibration)")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_slopes)

    p = sub.add_parser("reconstructor", help="build the tomographic reconstructors of a case")
    p.add_argument("--spec", required=True, help="reconstructor spec as JSON")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_reconstructor)

    p = sub.add_parser("commands", help="build the AO command matrix of a case")
    p.add_argument("--spec", required=True, help="command-matrix spec as JSON")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_commands)

    p = sub.add_parser("calibration", help="measure the WFS slope response of a case")
    p.add_argument("--spec", required=True, help="calibration spec as JSON")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_calibration)

    p = sub.add_parser("lucky", help="detector noise, selection, shift-and-add, scores")
    p.add_argument("--settings", required=True, help="lucky settings as JSON")
    p.add_argument("--frames", default="", help="frame cube (none: every target replayed, replay_frames)")
    p.add_argument("--telemetry", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--screens", default="", help="screens, to replay the targets the simulation did not image")
    p.add_argument("--screens-metadata", default="")
    p.add_argument("--learned-model", default="", help="the case's learned model (ao.learned_training_seed)")
    p.set_defaults(func=cmd_lucky)

    p = sub.add_parser("learn", help="fit the learned criterion on a training twin's telemetry")
    p.add_argument("--telemetry", required=True, help="the training twin's telemetry.nc")
    p.add_argument("--out", required=True, help="the model (.nc) to write")
    p.set_defaults(func=cmd_learn)

    p = sub.add_parser("figure", help="draw one figure and write its data")
    p.add_argument("--id", required=True)
    given = p.add_mutually_exclusive_group(required=True)
    given.add_argument("--settings", help="figure settings as JSON")
    given.add_argument("--settings-file", help="figure settings as a JSON file")
    p.add_argument("--out-prefix", required=True)
    p.add_argument("inputs", nargs="*", help="lucky.nc files of the figure's cases, in order")
    p.set_defaults(func=cmd_figure)

    p = sub.add_parser("export", help="a case's integrated and long-exposure images as FITS (INDEX: extension 1)")
    p.add_argument("lucky", help="the case's lucky.nc")
    p.add_argument("--out", required=True, help="FITS file to write")
    p.add_argument("--detector", nargs="+", help="only these detectors (default: all)")
    p.add_argument("--registration", nargs="+", help="only these registration methods (default: all)")
    p.add_argument(
        "--cube",
        action="store_true",
        help="a cube per target, registration, criterion and detector, the fraction selected as its "
        "third axis (for DS9); default: an image extension per image",
    )
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("table", help="a long_exposure_table figure's data as a Markdown table")
    p.add_argument("data", help="the figure's .nc, e.g. figures/longexp.nc")
    p.set_defaults(func=cmd_table)

    p = sub.add_parser("knees", help="a registration figure's knees as a Markdown table")
    p.add_argument("data", help="the figure's .nc, e.g. figures/registration.nc")
    p.add_argument("--fraction", type=float, help="fraction of frames (default: the figure's first)")
    p.add_argument("--criterion", default="lgs_rms", help="selection criterion (default lgs_rms)")
    p.add_argument("--read-noise", type=float, default=0.1, help="read noise [e-] (default 0.1)")
    p.set_defaults(func=cmd_knees)

    p = sub.add_parser("archive", help="one tar file of a finished study, with checksums")
    p.add_argument("--study-dir", default=".", help="the study folder Snakemake ran in (default: here)")
    p.add_argument("--configfile", nargs="+", default=[], help="the overlays given to Snakemake's --configfile")
    p.add_argument("--out", help="archive path (default: STUDY_DIR/archives/luckyao-<config hash>-<UTC time>.tar)")
    p.set_defaults(func=cmd_archive)

    p = sub.add_parser("verify", help="check an archive's checksums, rerun one case and compare its numbers")
    p.add_argument("archive")
    p.add_argument("--case", help="case to rerun (default: the one whose jobs took least time)")
    p.add_argument("--all-cases", action="store_true", help="rerun every archived case (the whole study's time)")
    p.add_argument("--workdir", help="folder of the rerun, kept (default: a scratch folder)")
    p.add_argument("--rtol", type=float, default=0.0, help="relative tolerance (default 0: bit-identical)")
    p.add_argument("--atol", type=float, default=0.0, help="absolute tolerance (default 0)")
    p.add_argument("--cores", type=int, default=2, help="Snakemake cores of the rerun")
    p.add_argument("--snakefile", help="workflow of the rerun (default: this checkout's)")
    p.add_argument("--no-rerun", action="store_true", help="checksums and versions only")
    p.set_defaults(func=cmd_verify)

    p = sub.add_parser(
        "lock",
        help="print (or --out) the exact versions of a study's runtime packages, as an archive stores them "
        "(the .venv's requirements.lock: bash run.sh lock)",
    )
    p.add_argument("--out", help="file to write")
    p.set_defaults(func=cmd_lock)

    return parser


if __name__ == "__main__":
    sys.exit(main())
