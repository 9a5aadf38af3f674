"""``posecons study``: argument checks and printing over :mod:`posecons.study.runner` and :mod:`posecons.study.report`."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import PoseconsError
from .arguments import add_accelerator, add_command, non_negative_int, output_file, output_folder, positive_int


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(subparsers, "study", study_command)
    p.add_argument("--spec", help="study spec: a YAML file or a bundled name (study/synth, study/kitti_gpu)")
    p.add_argument("--out", type=output_folder, help="study folder: data, runs, results/*.json, results.md")
    p.add_argument(
        "--report",
        type=output_file,
        metavar="PATH",
        help="the report (default OUT/results.md); its figures and JSON copies go beside it (docs/study.md)",
    )
    p.add_argument("--report-only", action="store_true", help="train nothing: rebuild the report from the JSONs")
    p.add_argument(
        "--results", type=Path, metavar="DIR", help="with --report-only: the folder of JSONs (default OUT/results)"
    )
    p.add_argument(
        "--variants", nargs="+", metavar="NAME", help="only these of the spec's variants, and its reference (the first)"
    )
    p.add_argument("--seeds", nargs="+", type=non_negative_int, metavar="K", help="these seeds in place of the spec's")
    p.add_argument("--data-path", type=Path, help="KITTI raw root, in place of the spec's data.path")
    p.add_argument("--odometry-path", type=Path, help="KITTI odometry root, in place of the spec's data.odometry")
    add_accelerator(p)
    p.add_argument(
        "--jobs",
        type=positive_int,
        default=1,
        help="runs side by side, each in its own process with the CPU threads shared out (default 1); "
        "on a 2-core CPU, 2 get about 1.2× the steps of 1",
    )
    p.add_argument("--quiet", action="store_true", help="no per-step progress bar while a run trains")


def study_command(args: argparse.Namespace) -> int:
    """variants × seeds → runs → evaluation → results report with paired differences

    Train every (variant, seed) of a study spec, evaluate each run's last weights, and write a report;
    rerunning it skips finished runs and resumes interrupted ones."""
    if args.report_only:
        return _report_only(args)
    if args.results is not None:
        raise PoseconsError("--results is for --report-only (a study writes its results into OUT/results)")
    if not (args.spec and args.out):
        raise PoseconsError("a study needs --spec and --out (or --report-only to rebuild a report)")
    from ..study.runner import run_study
    from ..study.spec import load_spec

    spec = load_spec(args.spec, args.data_path, args.odometry_path).select(args.variants, args.seeds)
    report = args.report or args.out / "results.md"
    trained = run_study(spec, args.out, report, args.report is not None, args.accelerator, args.quiet, args.jobs)
    print(f"report: {report} ({trained} runs trained or resumed now, {len(spec.runs())} in the spec)")
    return 0


def _report_only(args: argparse.Namespace) -> int:
    from ..study.report import write_report
    from ..study.spec import load_spec

    if args.results is None and args.out is None:
        raise PoseconsError("--report-only needs --results DIR (a folder of study JSONs) or --out")
    results = args.results or args.out / "results"
    report = args.report or (args.out / "results.md" if args.out else None)
    if report is None:
        raise PoseconsError("--report-only with --results needs --report PATH (where to write the report)")
    if not results.is_dir():
        raise PoseconsError(f"--results {results}: no such folder")
    study = (
        load_spec(args.spec, args.data_path, args.odometry_path).select(args.variants, args.seeds).describe()
        if args.spec
        else None
    )
    write_report(results, report, study, publish=args.report is not None)
    print(f"report: {report}")
    return 0
