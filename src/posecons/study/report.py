"""The study report, from the result JSONs alone: depth in the paper's Table 1 layout (frame and
per-sequence median scaling), pose in its Table 3 layout, paired differences from the reference
variant with exact paired tests (metrics.stats), and Figure 1 (per-frame scales) for the reference and the most
scale-consistent variant. ``--report-only`` rebuilds it from a folder of JSONs (e.g. committed ones).
"""

from __future__ import annotations

import json
import math
import re
import shutil
from collections.abc import Callable, Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

from ..errors import PoseconsError
from ..evaluation.compare import DIGITS, EIGEN_COLUMNS, markdown_table, table1
from ..fileio import output_dir, write_text
from ..metrics.stats import ALPHA, MIN_SEEDS, POWER, compare, mean_std, paired_differences
from .spec import CONSTANT, FLOOR, UNTRAINED

STUDY_FILE = "study.json"
FAILED = "failed"  # the subfolder of the failed runs' records
Getter = Callable[[dict], Any]
POSE_COLUMNS = (
    ("ate_mean", "snippet ATE mean", ".4f"),
    ("ate_std", "snippet ATE std", ".4f"),
    ("ate_full_rmse", "full ATE (m)", ".3f"),
    ("t_err", "t_err (%)", ".2f"),
    ("r_err", "r_err (°/100 m)", ".2f"),
)
# Results written before t_err / r_err had them as rpe_trans (%) and rpe_rot (°/m): the same segments
# of the Sim(3)-aligned trajectory, so the committed JSONs still fill the columns.
LEGACY_POSE_KEYS = {"t_err": ("rpe_trans", 1.0), "r_err": ("rpe_rot", 100.0)}


def load_study(folder: Path) -> dict:
    """The ``study.json`` a study wrote into its results folder."""
    path = Path(folder) / STUDY_FILE
    if not path.is_file():
        raise PoseconsError(f"{folder}: no {STUDY_FILE}, so not the results folder of a posecons study")
    return read_json(path)


def load_results(folder: Path) -> list[dict]:
    """Every run's result JSON in ``folder`` (all ``*.json`` but study.json)."""
    results = []
    for path in sorted(Path(folder).glob("*.json")):
        if path.name == STUDY_FILE or path.name.startswith("."):
            continue
        result = read_json(path)
        if not {"variant", "seed", "depth"} <= set(result):
            raise PoseconsError(f"{path}: not a study result (no variant, seed and depth)")
        results.append(result)
    return results


def load_failures(folder: Path) -> list[dict]:
    """The records of the runs that failed (``folder/failed/*.json``), until a rerun succeeds."""
    return [read_json(p) for p in sorted((Path(folder) / FAILED).glob("*.json"))]


def read_json(path: Path) -> dict:
    """A JSON file of the study; a damaged one is an error naming it."""
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise PoseconsError(f"{path}: not valid JSON ({exc})") from None


def _number(value: Any) -> float:
    return float(value) if isinstance(value, (int, float)) else math.nan


def _values(results: Sequence[dict], get: Getter) -> dict[str, dict[int, float]]:
    """variant → {seed: value} (NaN where the value is missing)."""
    out: dict[str, dict[int, float]] = {}
    for r in results:
        out.setdefault(r["variant"], {})[int(r["seed"])] = _number(get(r))
    return out


def cell(values: Sequence[float], fmt: str) -> str:
    """'mean ± std' over seeds; the mean alone for one seed; '–' for none."""
    mean, std = mean_std(values)
    if math.isnan(mean):
        return "–"
    return f"{mean:{fmt}}" if math.isnan(std) else f"{mean:{fmt}} ± {std:{fmt}}"


def _rows(names: Sequence[str], columns: Sequence[tuple[Getter, str]], results: Sequence[dict]) -> list[list[str]]:
    """One row per variant name: its number of seeds, then each column's cell over them."""
    rows = []
    for name in names:
        mine = [r for r in results if r["variant"] == name]
        rows.append([name, str(len(mine))] + [cell([_number(get(r)) for r in mine], fmt) for get, fmt in columns])
    return rows


def _depth(scaling: str, key: str) -> Getter:
    return lambda r: r["depth"].get(scaling, {}).get(key)


def _sequence_cv(name: str) -> Getter:
    return lambda r: r["depth"]["frame"].get("per_sequence", {}).get(name, {}).get("scale_cv")


def _pose(seq: str, key: str, baseline: bool = False) -> Getter:
    def get(r: dict) -> Any:
        result = r.get("pose", {}).get(seq, {})
        result = result.get("const_velocity", {}) if baseline else result
        if key not in result and key in LEGACY_POSE_KEYS:
            old, factor = LEGACY_POSE_KEYS[key]
            return _number(result.get(old)) * factor
        return result.get(key)

    return get


def depth_tables(names: Sequence[str], results: Sequence[dict]) -> str:
    """Table 1 with frame-median scaling (σ/μ per test sequence, their mean, pooled σ/median, Eigen
    metrics) and the Eigen metrics again with per-sequence scaling."""
    from ..plots import short_name

    sequences = list(results[0]["depth"]["frame"].get("per_sequence", {}))
    frame_cols = [(_sequence_cv(s), ".4f") for s in sequences] + [
        (_depth("frame", "scale_cv"), ".4f"),
        (_depth("frame", "scale_std_over_median"), ".4f"),
    ]
    frame_cols += [(_depth("frame", key), DIGITS) for key, _, _ in EIGEN_COLUMNS]
    scale = [f"σ/μ {short_name(s)}" for s in sequences] + ["σ/μ mean", "σ/median pooled"]
    seq_cols = [(_depth("sequence", key), DIGITS) for key, _, _ in EIGEN_COLUMNS]
    return (
        "### Frame-median scaling (each frame scaled by median(gt)/median(pred))\n\n"
        + table1(_rows(names, frame_cols, results), ["variant", "n"], scale)
        + "\n### Per-sequence scaling (one factor per sequence: the median of its frame scales)\n\n"
        "σ/μ does not depend on the scaling (it is computed from the same per-frame scales), so only the "
        "error metrics are repeated; with one factor per sequence, a scale that drifts within a sequence "
        "shows up as error.\n\n" + table1(_rows(names, seq_cols, results), ["variant", "n"], [])
    )


def pose_tables(names: Sequence[str], results: Sequence[dict]) -> str:
    """Table 3 per test sequence: snippet ATE beside full ATE and t_err / r_err, and the constant-velocity row."""
    sequences = list(dict.fromkeys(seq for r in results for seq in r.get("pose", {})))
    if not sequences:
        return "No pose evaluation (the spec names no odometry sequences).\n"
    text = []
    for seq in sequences:
        columns = [(_pose(seq, key), fmt) for key, _, fmt in POSE_COLUMNS]
        rows = _rows(names, columns, results)
        baseline = next(r for r in results if seq in r.get("pose", {}))  # the same for every run: GT only
        rows.append(
            ["constant velocity (no images)", "–"]
            + [cell([_number(_pose(seq, key, True)(baseline))], fmt) for key, _, fmt in POSE_COLUMNS]
        )
        text.append(
            f"### Odometry sequence {seq}\n\n"
            + markdown_table(["variant", "n"] + [h for _, h, _ in POSE_COLUMNS], rows)
        )
    return "\n".join(text)


PRIMARY = "mean σ/μ"  # the study's pre-declared primary metric: the weights evaluated (EMA where kept)


def paired_metrics(results: Sequence[dict]) -> list[tuple[str, Getter, str]]:
    """(label, getter, format) of the metrics compared seed by seed; the first is :data:`PRIMARY`."""
    metrics = [
        (PRIMARY, _depth("frame", "scale_cv"), ".4f"),
        ("abs rel", _depth("frame", "abs_rel"), ".4f"),
        ("abs rel, per-seq. scaling", _depth("sequence", "abs_rel"), ".4f"),
        ("δ<1.25", _depth("frame", "a1"), ".4f"),
    ]
    for seq in dict.fromkeys(seq for r in results for seq in r.get("pose", {})):
        metrics += [(f"snippet ATE {seq}", _pose(seq, "ate_mean"), ".4f")]
        metrics += [(f"full ATE {seq}", _pose(seq, "ate_full_rmse"), ".3f")]
    return metrics


def run_kind(result: dict) -> str:
    """How a run computed, beside its seed: its compute threads and its processor. A run's
    trajectory depends on both as much as on its seed (another thread count, AVX2 kernels in place
    of AVX-512 ones, AMX or another processor model of the same kind rounds differently from the first
    step on), so a run is paired only with a reference run of its own kind. Results written before a
    field was recorded say so, and pair only with each other."""
    env = result.get("environment", {})
    machine = env.get("machine", "")
    used = re.search(r"(\d+) used(, (.+))?$", machine)
    threads = env.get("threads", used.group(1) if used else "unrecorded")
    gpu = f", {used.group(3)}" if used and used.group(3) else ""
    processor = f" ({env['processor']})" if "processor" in env else ""
    return f"{threads} thread(s), CPU {env.get('cpu', 'unrecorded')}{processor}{gpu}"


def pair_alike(variants: Sequence[str], results: Sequence[dict]) -> tuple[list[dict], list[str]]:
    """(the runs of ``variants`` that the reference's run of the same seed computed alike, the others
    as 'variant seeds k, l (their kind; the reference's)' lines); see :func:`run_kind`."""
    kinds = {(r["variant"], int(r["seed"])): run_kind(r) for r in results if r["variant"] in variants}
    alike, apart = [], {}
    for r in results:
        variant, seed = r["variant"], int(r["seed"])
        if variant not in variants:
            continue
        reference = kinds.get((variants[0], seed))
        if reference in (None, kinds[variant, seed]):
            alike.append(r)
        else:
            apart.setdefault((kinds[variant, seed], reference), {}).setdefault(variant, []).append(seed)
    left_out = []
    for (kind, reference), seeds in apart.items():
        runs = "; ".join(
            f"{v} seed{'s' * (len(seeds[v]) > 1)} {', '.join(map(str, sorted(seeds[v])))}"
            for v in variants
            if v in seeds
        )
        left_out.append(f"{runs} ({kind}; {variants[0]}: {reference})")
    return alike, left_out


def paired_rows(variants: Sequence[str], results: Sequence[dict]) -> list[dict]:
    """For each metric and each variant but the reference (the first): the statistics of its per-seed
    differences from the reference (:func:`~posecons.metrics.stats.compare`), over the seeds whose two
    runs computed alike (:func:`run_kind`). Holm's correction runs over the variants for the primary
    metric, and over every row of the secondary metrics together, so that neither the variants nor the
    many secondary rows inflate the verdicts."""
    alike = pair_alike(variants, results)[0]
    differences = {}
    for label, get, fmt in paired_metrics(results):
        values = _values(alike, get)
        diffs = paired_differences({v: values.get(v, {}) for v in variants}, variants[0])
        differences.update({(label, fmt, v): diffs[v] for v in variants[1:]})
    rows = []
    for primary in (True, False):
        family = {key: d for key, d in differences.items() if (key[0] == PRIMARY) == primary}
        for (label, fmt, variant), stats in compare(family).items():
            rows.append({"metric": label, "variant": variant, "format": fmt, "primary": primary, **stats})
    return rows


def paired_table(rows: Sequence[dict], reference: str) -> str:
    """One line per comparison. Below :data:`MIN_SEEDS` seeds no interval, p or MDE is printed: no
    exact test can reach the level there, and an interval of so few seeds would claim more than it holds.
    The SD of the differences is always printed: it sizes the seeds a verdict needs."""
    cells = []
    for r in rows:
        fmt, testable = r["format"], r["n"] >= MIN_SEEDS
        metric = f"**{r['metric']}** (primary)" if r["primary"] else r["metric"]
        if r["n"] == 0:
            cells.append([metric, r["variant"], "0"] + ["–"] * 7 + [r["verdict"]])
            continue
        numbers = [
            f"[{r['low']:+{fmt}}, {r['high']:+{fmt}}]",
            f"{r['p']:.3f}",
            f"{r['p_holm']:.3f}",
            f"{r['mde']:{fmt}}",
        ]
        verdict = r["verdict"] if r["verdict"] != "not shown" else f"not shown (MDE {r['mde']:{fmt}})"
        cells.append(
            [
                metric,
                r["variant"],
                str(r["n"]),
                f"{r['mean']:+{fmt}}",
                "–" if math.isnan(r["sd"]) else f"{r['sd']:{fmt}}",
            ]
            + (numbers if testable else ["–"] * 4)
            + [r["signs"], verdict]
        )
    header = [
        "metric",
        f"variant − {reference}",
        "n seeds",
        "mean difference",
        "SD",
        f"{1 - ALPHA:.0%} t-interval",
        "p (exact sign-flip)",
        "p (Holm)",
        f"MDE ({POWER:.0%} power)",
        "signs",
        "verdict",
    ]
    return markdown_table(header, cells)


def _figure1(variants: Sequence[str], results: Sequence[dict], figures: Path) -> str:
    """Figure 1 (box plot per sequence, scale over time) for the reference and the variant with the
    lowest mean σ/μ, from one seed both have."""
    from ..plots import plot_scale_boxplots, plot_scales_over_time

    cv = {v: mean_std(list(_values(results, _depth("frame", "scale_cv")).get(v, {}).values()))[0] for v in variants}
    others = [v for v in variants[1:] if not math.isnan(cv[v])]
    chosen = [variants[0]] + ([min(others, key=cv.get)] if others else [])
    seeds = sorted(set.intersection(*({int(r["seed"]) for r in results if r["variant"] == v} for v in chosen)))
    if math.isnan(cv[variants[0]]) or not seeds:
        return "No figure yet: the reference variant has no finished run.\n"
    seed = seeds[0]
    runs = {v: next(r for r in results if r["variant"] == v and int(r["seed"]) == seed) for v in chosen}
    lines = [line.split() for line in runs[variants[0]]["test_lines"]]
    sequences, frames = [line[0] for line in lines], [int(line[1]) for line in lines]
    scales = {v: [math.nan if s is None else s for s in runs[v]["depth"]["frame"]["scales"]] for v in chosen}
    plot_scale_boxplots(scales, sequences, figures / "scale_boxplot.png", normalise=True)
    plot_scales_over_time(scales, sequences, frames, figures / "scale_over_time.png", count=3, normalise=True)
    which = f"**{chosen[0]}** (reference)" + (
        f" and **{chosen[1]}** (of the other variants, the lowest mean σ/μ)" if len(chosen) > 1 else ""
    )
    return (
        f"{which}, seed {seed}. Each run's per-frame scales median(gt)/median(pred), divided by their "
        "median over the test set (a monocular network's overall scale is arbitrary; the spread is what "
        f"σ/μ measures).\n\n![scale box plot]({figures.name}/scale_boxplot.png)\n\n"
        f"![scale over time]({figures.name}/scale_over_time.png)\n"
    )


# A run has learnt when its abs rel (frame-median scaling) is at least this share below a constant depth's.
LEARN_MARGIN = 0.2


def learning_table(variants: Sequence[str], results: Sequence[dict]) -> str:
    """The study's first row: how many runs of each variant learnt (abs rel ≤ (1 − LEARN_MARGIN) × a
    constant depth's), and the seeds of those that did not."""
    constant = next((r for r in results if r["variant"] == CONSTANT), None)
    if constant is None:
        return "No constant-depth row yet: whether the runs learnt is not judged.\n"
    bar = (1 - LEARN_MARGIN) * constant["depth"]["frame"]["abs_rel"]
    rows = []
    for v in variants:
        runs = sorted((r for r in results if r["variant"] == v), key=lambda r: r["seed"])
        failed = [
            f"{r['seed']} ({r['depth']['frame']['abs_rel']:.3f})"
            for r in runs
            if not r["depth"]["frame"]["abs_rel"] <= bar
        ]
        rows.append([v, f"{len(runs) - len(failed)} of {len(runs)}", ", ".join(failed) or "–"])
    return (
        f"A run has learnt when its abs rel is at most {bar:.3f}: {LEARN_MARGIN:.0%} below a constant depth's "
        f"({constant['depth']['frame']['abs_rel']:.3f}, frame-median scaling).\n\n"
        + markdown_table(["variant", "runs that learnt", "seeds that did not (abs rel)"], rows)
    )


def _missing(study: dict, results: Sequence[dict]) -> tuple[list[str], list[str], int]:
    """(missing runs, missing untrained seeds, runs done) against the spec's variants × seeds."""
    have = {(r["variant"], int(r["seed"])) for r in results}
    runs = [(v, s) for s in study["seeds"] for v in study["variants"]]
    missing = [f"{v} seed {s}" for v, s in runs if (v, s) not in have]
    untrained = [str(s) for s in study["seeds"] if (UNTRAINED, s) not in have]
    return missing, untrained, len(runs) - len(missing)


def _data_line(data: dict) -> str:
    if "synth" in data:
        s = data["synth"]
        return (
            f"synthetic KITTI-format data (`posecons synth`: {s['drives']} drives × {s['frames']} frames, "
            f"{s['width']}×{s['height']}, ±{s['neighbours']} neighbours, seed {s['seed']}), its held-out drives"
        )
    if "rgbd" in data:
        r = data["rgbd"]
        held_out = (
            f"frames from {r['test_from']} on, {r['gap']} left out before them" if r["test_from"] else "every frame"
        )
        return (
            f"RGB-D sequence `{r['input']}` (one frame in {r['every']}; test stretch: {held_out}), its depth "
            f"images as ground truth ({r['min_depth']:g}–{r['max_depth']:g} m, no crop) and its poses as odometry 00"
        )
    pose = (
        f"; odometry `{data['odometry']}` sequences {', '.join(data['odometry_sequences'])}"
        if "odometry" in data
        else ""
    )
    return f"KITTI raw `{data['path']}`, test split `{data['test_split']}` (LiDAR ground truth){pose}"


def report_text(study: dict, results: Sequence[dict], figures: Path, failures: Sequence[dict] = ()) -> str:
    """The whole report (Markdown); writes its figures into ``figures``."""
    from ..plots import plot_paired_differences

    variants = list(study["variants"])
    references = [n for n in (FLOOR, CONSTANT) if any(r["variant"] == n for r in results)]
    names = [UNTRAINED, *references, *variants]
    missing, untrained_missing, done = _missing(study, results)
    runs = len(study["seeds"]) * len(variants)
    envs = [r["environment"] for r in results if "environment" in r]
    code = "; ".join(
        dict.fromkeys(
            f"commit `{e['commit']}` on {e['machine']}{', CPU ' + e['cpu'] if 'cpu' in e else ''}"
            f"{' (' + e['processor'] + ')' if 'processor' in e else ''} (torch {e['torch']})"
            for e in envs
        )
    )
    trained = [r for r in results if r["variant"] not in (UNTRAINED, FLOOR, CONSTANT)]
    failed = "".join(
        f"\n- **failed** (the same command retries it): {f['variant']} seed {f['seed']}: {f['error']} (log: `{f['log']}`)"
        for f in failures
    )
    overview = markdown_table(
        ["variant", "overrides (after the spec's)", "runs done", "steps", "train minutes"],
        [
            [
                v + (" (reference)" if v == variants[0] else ""),
                ", ".join(f"`{o}`" for o in study["variants"][v]) or "–",
                str(sum(r["variant"] == v for r in trained)),
                cell([r["steps"] for r in trained if r["variant"] == v], ".0f"),
                # a result evaluated from weights kept at a step of a longer run has no time of its own
                cell([r["train_minutes"] for r in trained if r["variant"] == v and "train_minutes" in r], ".1f"),
            ]
            for v in variants
        ],
    )
    header = f"""# Study: {Path(study["spec"]).name}

- spec: `{study["spec"]}`; preset `{study["preset"]}`; overrides for every run: {", ".join(f"`{o}`" for o in study["overrides"]) or "none"}
- data: {_data_line(study["data"])}
- seeds: {", ".join(map(str, study["seeds"]))} (`train.seed`: the same initial weights and data order for every variant of a seed)
- code and machine: {code or "–"}
- compute threads per run: {f"{study['threads']}, pinned by the spec" if study.get("threads") else "not pinned by the spec (each run's count is in its machine above)"}
- generated: {datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")}
- runs done: {done} of {runs}{"; missing: " + ", ".join(missing) if missing else ""}{"; untrained missing for seeds " + ", ".join(untrained_missing) if untrained_missing else ""}{failed}
- weights evaluated: each run's `checkpoints/last.pt`, the last step (no model selection, no ground truth);
  `untrained` is the initial network of each seed; `renderer_depth` (synthetic data) is the renderer's
  exact depth evaluated as a prediction, the floor no network can beat here
- cells: mean ± sample std over the seeds done (n); one value when n = 1

{overview}"""
    if not results:
        return header + "\nNo results yet.\n"
    paired = paired_rows(variants, results)
    figure = ""
    if len(variants) > 1 and any(r["n"] for r in paired):
        plot_paired_differences([r for r in paired if r["n"]], figures / "paired_differences.png")
        figure = f"\n![paired differences]({figures.name}/paired_differences.png)\n"
    n = sorted({r["n"] for r in paired}) or [0]
    comparison = paired_table(paired, variants[0]) if paired else "Only one variant: nothing to compare.\n"
    left_out = pair_alike(variants, results)[1]
    if left_out:
        comparison += (
            f"\nNot paired, since {variants[0]}'s run of the same seed computed differently (the difference "
            "would hold the machine's effect as well as the variant's): " + "; ".join(left_out) + ".\n"
        )
    return f"""{header}
## Runs that learnt

{learning_table(variants, results)}
## Depth (paper Table 1 layout)

Test: {_data_line(study["data"])}{"" if "rgbd" in study["data"] else "; Garg crop"}; σ/μ per sequence of the per-frame scales, their mean
(the paper's σ/μ) and the pooled std(s / median(s)) over all frames (as Monodepth2 prints it).

{depth_tables(names, results)}
## Ego-motion (paper Table 3 layout)

Snippet ATE: 5-frame snippets, each scaled to the ground truth by least squares (mean and std over
snippets); full ATE: the chained trajectory after Sim(3) alignment; t_err / r_err: the KITTI
odometry devkit's errors of the Sim(3)-aligned trajectory over 100–800 m segments (10–80 % of the
path on sequences under 100 m, which the devkit cannot score). The constant-velocity row repeats the
first ground-truth step and needs no images.

{pose_tables(names, results)}
## Paired differences from {variants[0]}

Per seed, variant − {variants[0]} (the same seed: the same initial weights and data order). The primary
metric, declared before the runs, is the mean σ/μ of the weights evaluated (the EMA where the recipe
keeps one); the others are secondary. Each comparison: the mean difference, its {1 - ALPHA:.0%} Student-t
interval, the exact two-sided p of the paired sign-flip test (all 2ⁿ sign assignments), that p after
Holm's correction (over the variants for the primary metric; over all secondary rows together), and the
minimal detectable effect (MDE) of a paired t-test at α = {ALPHA} with {POWER:.0%} power for the observed
SD. "lower"/"higher": Holm-corrected p < {ALPHA}; "not shown": not, with the effect this many seeds
could have shown. The smallest exact p is 2/2ⁿ, so below {MIN_SEEDS} seeds no verdict is possible
("untestable") and no interval is printed. n = {", ".join(map(str, n))} seeds. Lower is better for σ/μ,
abs rel and ATE; higher for δ<1.25.

{comparison}{figure}
## Figure 1: per-frame scale

{_figure1(variants, results, figures)}"""


def write_report(results_dir: Path, report: Path, study: dict | None = None, publish: bool = False) -> Path:
    """Write ``report`` (Markdown) and its figures into the folder beside it named after it
    (docs/results.md → docs/results/); with ``publish`` also copy the JSONs (and study.json) into that
    folder's ``json/``, so the report can be rebuilt from committed files alone."""
    results_dir, report = Path(results_dir), Path(report)
    study = study or load_study(results_dir)
    figures = report.with_suffix("")
    # Only the study's runs: a results folder shared by several specs, or a --seeds/--variants
    # selection, holds others, which would otherwise enter the means and the pairs.
    names = {UNTRAINED, FLOOR, CONSTANT, *study["variants"]}
    results = [
        r
        for r in load_results(results_dir)
        if r["variant"] in names and (r["variant"] in (FLOOR, CONSTANT) or r["seed"] in study["seeds"])
    ]
    in_study = [f for f in load_failures(results_dir) if f["variant"] in names and f["seed"] in study["seeds"]]
    text = report_text(study, results, figures, in_study)
    copies = figures / "json"
    if publish and copies.resolve() != results_dir.resolve():
        with output_dir(copies) as tmp:
            for path in sorted(results_dir.glob("*.json")):
                if not path.name.startswith("."):
                    shutil.copyfile(path, tmp / path.name)
    write_text(report, text)
    return report
