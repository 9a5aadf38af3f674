"""Markdown tables: the one renderer of the paper's Table 1 layout (``compare``, ``evaluate-depth``,
the demo's and a study's reports), and Table 1 from depth-evaluation JSON files."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

from ..errors import PoseconsError

# (JSON key, column header, higher is better) of the paper's Table 1: σ/μ, the mean over sequences
# of the frame scales' σ/μ, then the Eigen metrics (a_k is δ < 1.25^k).
EIGEN_COLUMNS = (
    ("abs_rel", "Abs Rel", False),
    ("sq_rel", "Sq Rel", False),
    ("rmse", "RMSE", False),
    ("rmse_log", "RMSE log", False),
    ("a1", "δ<1.25", True),
    ("a2", "δ<1.25²", True),
    ("a3", "δ<1.25³", True),
)
TABLE1_COLUMNS = (("scale_cv", "σ/μ", False), *EIGEN_COLUMNS)
DIGITS = ".3f"  # as the paper prints them
RUN_RESULT = Path("eval") / "depth.json"  # where a run directory keeps its depth evaluation


def load_result(path: str | Path) -> dict:
    """A depth-evaluation dict from a JSON file, or from ``<run>/eval/depth.json`` for a run directory."""
    path = Path(path)
    file = path / RUN_RESULT if path.is_dir() else path
    if not file.is_file():
        raise PoseconsError(
            f"{file}: no such evaluation JSON" + (" (run directory without eval/depth.json)" if path.is_dir() else "")
        )
    try:
        result = json.loads(file.read_text())
    except json.JSONDecodeError as exc:
        raise PoseconsError(f"{file}: not valid JSON ({exc})") from None
    missing = [key for key, _, _ in TABLE1_COLUMNS if key not in result]
    if missing:
        raise PoseconsError(f"{file}: not a depth evaluation, missing {', '.join(missing)}")
    return result


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table: the first column left-aligned (names), the others right-aligned (numbers)."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join([" --- "] + [" ---: "] * (len(header) - 1)) + "|"]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in rows]) + "\n"


def table1(rows: Sequence[Sequence[str]], lead: Sequence[str] = ("Method",), scale: Sequence[str] = ("σ/μ",)) -> str:
    """The paper's Table 1 layout: the ``lead`` columns (a row's name, ...), the scale-consistency
    columns ``scale`` (the paper's σ/μ; a study adds per-sequence ones), then the Eigen metrics of
    :data:`EIGEN_COLUMNS`; ``rows``: each row's printed cells in that order."""
    return markdown_table([*lead, *scale, *(header for _, header, _ in EIGEN_COLUMNS)], rows)


def result_cells(result: dict, scale_format: str = DIGITS) -> list[str]:
    """A depth result's printed Table-1 cells (:data:`TABLE1_COLUMNS`), σ/μ in ``scale_format``; '–'
    where a value is missing."""
    formats = [scale_format] + [DIGITS] * len(EIGEN_COLUMNS)
    return [_cell(result.get(key), fmt) for (key, _, _), fmt in zip(TABLE1_COLUMNS, formats)]


def _cell(value: float | None, fmt: str) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:{fmt}}"


def default_name(path: str | Path) -> str:
    """Row name for a result path: the run directory's name (also for ``<run>/eval/depth.json``), else the stem."""
    path = Path(path).resolve()
    if path.is_dir():
        return path.name
    return path.parents[1].name if path.parent.name == RUN_RESULT.parent.name else path.stem


def results_table(results: Sequence[dict], names: Sequence[str], bold: bool = True) -> str:
    """Table 1, one row per result; with ``bold`` the best value of each column (as printed) is bold."""
    if len(names) != len(results):
        raise PoseconsError(f"{len(names)} names for {len(results)} results")
    cells = [result_cells(result) for result in results]
    for col, (_, _, higher_better) in enumerate(TABLE1_COLUMNS if bold else ()):
        printed = [float(row[col]) for row in cells if row[col] != "–"]
        if printed:
            best = max(printed) if higher_better else min(printed)
            for row in cells:
                if row[col] != "–" and float(row[col]) == best:
                    row[col] = f"**{row[col]}**"
    notes = [
        f"- {name}: {checkpoint_note(result['checkpoint'])}\n"
        for name, result in zip(names, results)
        if "checkpoint" in result
    ]
    return table1([[name, *row] for name, row in zip(names, cells)]) + ("\n" + "".join(notes) if notes else "")


def checkpoint_note(info: dict) -> str:
    """One line naming the evaluated weights and how they were chosen (``describe_checkpoint``)."""
    step = f", step {info['step']}" if info.get("step") is not None else ""
    return (
        f"{Path(info['file']).name}{step}; selected by: {info['selected_by']}; "
        f"initialisation: {info.get('initialisation', 'not recorded')}; weights: {info.get('weights', 'not recorded')}"
    )
