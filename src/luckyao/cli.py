"""Command-line interface: one subcommand per workflow step.

    luckyao check CONFIG
    luckyao turbulence --spec JSON --screens S.npy --metadata S.nc
    luckyao simulate --case JSON --name NAME --seed N --screens S.npy --screens-metadata S.nc
                     [--reconstructor R.nc] --frames F --telemetry T
    luckyao reconstructor --spec JSON --out R.nc
    luckyao lucky --settings JSON --frames F --telemetry T --out lucky.nc
    luckyao figure --id ID --settings JSON --out-prefix figures/ID  lucky.nc ...
"""

import argparse
import json
import logging
import sys
import time


def _setup_logging() -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s",
                        stream=sys.stderr)


def cmd_check(args) -> None:
    from .config import load_study

    _, cases = load_study(args.config)
    print(f"{args.config}: valid, {len(cases)} cases")


def cmd_turbulence(args) -> None:
    from .datasets import provenance
    from .turbulence import write_screens

    spec = json.loads(args.spec)
    write_screens(spec, args.screens, args.metadata, provenance("luckyao normalised phase screens", spec, spec["seed"]))


def cmd_simulate(args) -> None:
    from .datasets import FrameWriter, open_dataset, provenance, write_dataset
    from .simulate import System, simulate
    from .turbulence import read_screens

    case = json.loads(args.case)
    system = System.from_config(case)
    screens = read_screens(args.screens, args.screens_metadata)
    sensing = None
    if args.reconstructor:
        from .sensing import LgsSensing

        reconstructors = open_dataset(args.reconstructor, "reconstructor")["reconstructor"].values
        sensing = LgsSensing(case, list(system.layers), screens, reconstructors, args.seed)
    attrs = provenance(f"luckyao frames of case {args.name}", case, args.seed)
    start = time.perf_counter()
    with FrameWriter(args.frames, len(system.targets), system.n_frames, system.camera.n_pixels,
                     system.camera.pixel_scale_arcsec, attrs) as writer:
        telemetry = simulate(system, screens, writer.write, sensing)
    elapsed = time.perf_counter() - start
    steps = system.n_frames * system.steps_per_frame
    logging.getLogger(__name__).info("simulated %d steps in %.1f s: %.3f ms per step (with I/O)",
                                     steps, elapsed, 1e3 * elapsed / steps)
    telemetry.attrs.update(provenance(f"luckyao telemetry of case {args.name}", case, args.seed))
    telemetry.attrs["case"] = args.name
    write_dataset(telemetry, args.telemetry)


def cmd_reconstructor(args) -> None:
    from .datasets import provenance, write_dataset
    from .reconstructor import build_reconstructors

    spec = json.loads(args.spec)
    ds = build_reconstructors(spec)
    ds.attrs.update(provenance("luckyao tomographic reconstructors", spec, 0))
    write_dataset(ds, args.out, compress=False)


def cmd_lucky(args) -> None:
    from .postprocess import lucky_case

    lucky_case(json.loads(args.settings), args.frames, args.telemetry, args.out)


def cmd_figure(args) -> None:
    from .figures import draw_figure

    draw_figure(args.id, json.loads(args.settings), args.inputs, args.out_prefix)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="luckyao", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("check", help="validate a study config")
    p.add_argument("config")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("turbulence", help="generate the shared normalised phase screens")
    p.add_argument("--spec", required=True, help="turbulence spec as JSON")
    p.add_argument("--screens", required=True, help="flat .npy of the screens")
    p.add_argument("--metadata", required=True, help="netCDF description of the screens")
    p.set_defaults(func=cmd_turbulence)

    p = sub.add_parser("simulate", help="run one case's time loop")
    p.add_argument("--case", required=True, help="resolved case config as JSON")
    p.add_argument("--name", required=True)
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--screens", required=True)
    p.add_argument("--screens-metadata", required=True)
    p.add_argument("--reconstructor", default="", help="reconstructor file (cases with LGS)")
    p.add_argument("--frames", required=True)
    p.add_argument("--telemetry", required=True)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("reconstructor", help="build the tomographic reconstructors of a case")
    p.add_argument("--spec", required=True, help="reconstructor spec as JSON")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_reconstructor)

    p = sub.add_parser("lucky", help="detector noise, selection, shift-and-add, scores")
    p.add_argument("--settings", required=True, help="lucky settings as JSON")
    p.add_argument("--frames", required=True)
    p.add_argument("--telemetry", required=True)
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_lucky)

    p = sub.add_parser("figure", help="draw one figure and write its data")
    p.add_argument("--id", required=True)
    p.add_argument("--settings", required=True, help="figure settings as JSON")
    p.add_argument("--out-prefix", required=True)
    p.add_argument("inputs", nargs="*", help="lucky.nc files of the figure's cases, in order")
    p.set_defaults(func=cmd_figure)

    args = parser.parse_args(argv)
    _setup_logging()
    try:
        args.func(args)
    except (ValueError, OSError) as err:
        logging.getLogger("luckyao").exception("%s", err)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
