"""Results of earlier runs taken into a study folder as its own, once reruns on this machine have
reproduced earlier runs exactly — so that runs trained before a result recorded its CPU kind (or as the
first steps of a longer recipe, at_steps.py) pair with the runs trained here.

The report pairs a run only with a reference run that computed alike (same threads, CPU kind and
processor; docs/results.md §8). A result written before that record reads "unrecorded" and pairs with nothing
recorded. If ``--check RERUN=OLD`` holds — every number of the rerun's depth and pose results equal
to the old result's, to the last digit — the old runs computed as this machine does, and each SOURCE
is written to OUT/results with the rerun's threads, CPU kind and processor, the spec's config and overrides of
its variant and seed, and an ``adopted`` record naming the source file and the checks.

    python experiments/tools/adopt.py study/synth_fast runs/study_fast \\
        --check runs/study_fast/results/baseline_seed3.json=docs/results/study_fast/json/baseline_seed3.json \\
        docs/results/study_fast/json/cyc_seed3.json docs/results/study_bf16_at/step500/cyc_seed0.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from posecons.errors import PoseconsError
from posecons.fileio import write_json
from posecons.study.runner import result_name
from posecons.study.spec import load_spec


def numbers(value, path: str = "") -> dict[str, float]:
    """Every number in a JSON value by its path (texts — file names, commits — are not compared)."""
    if isinstance(value, dict):
        return {k: v for key, item in value.items() for k, v in numbers(item, f"{path}/{key}").items()}
    if isinstance(value, list):
        return {k: v for i, item in enumerate(value) for k, v in numbers(item, f"{path}/{i}").items()}
    return {path: value} if isinstance(value, (int, float)) or value is None else {}


def check(rerun: Path, old: Path) -> dict:
    """The rerun's environment, if its depth and pose numbers equal the old result's exactly."""
    new, before = json.loads(rerun.read_text()), json.loads(old.read_text())
    for key in ("depth", "pose", "raw_weights"):
        a, b = numbers(new.get(key, {})), numbers(before.get(key, {}))
        common = a.keys() & b.keys()  # a field added since the old run is not a difference
        if len(common) < len(b) // 2:
            raise PoseconsError(f"{rerun} and {old} share too few {key} numbers to compare ({len(common)})")
        differ = sorted(k for k in common if a[k] != b[k])
        if differ:
            raise PoseconsError(
                f"{rerun} does not reproduce {old}: {key}{differ[0]} {a.get(differ[0])} ≠ {b.get(differ[0])}"
            )
    return new["environment"]


def adopt(spec_name: str, out: Path, checks: list[tuple[Path, Path]], sources: list[Path]) -> list[Path]:
    spec = load_spec(spec_name)
    environments = [check(rerun, old) for rerun, old in checks]
    # what pairs a run (report.run_kind); the processor only where the reruns recorded it
    kinds = {tuple((k, e[k]) for k in ("threads", "cpu", "processor") if k in e) for e in environments}
    if len(kinds) != 1:
        raise PoseconsError(f"the reruns computed differently from each other: {sorted(kinds)}")
    kind = dict(kinds.pop())
    written = []
    for source in sources:
        result = json.loads(source.read_text())
        variant, seed = result["variant"], int(result["seed"])
        target = out / "results" / result_name(variant, seed)
        if target.exists():
            continue
        result.update(
            overrides=spec.run_overrides(variant, seed),
            config=spec.config(variant, seed).to_dict(),
            environment={**result.get("environment", {}), **kind},
            adopted={"from": str(source), "reproduced": [f"{rerun} = {old}" for rerun, old in checks]},
        )
        write_json(target, result)
        written.append(target)
        print(f"{source} → {target}")
    return written


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spec", help="the study's spec, e.g. study/synth_fast")
    p.add_argument("out", type=Path, help="the study folder (its results/ receives the sources)")
    p.add_argument("sources", type=Path, nargs="+", help="result JSONs of earlier runs")
    p.add_argument(
        "--check", action="append", required=True, metavar="RERUN=OLD", help="a rerun and the old result it must equal"
    )
    args = p.parse_args()
    try:
        checks = [tuple(Path(part) for part in pair.split("=", 1)) for pair in args.check]
        adopt(args.spec, args.out, checks, args.sources)
    except (PoseconsError, OSError, ValueError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
