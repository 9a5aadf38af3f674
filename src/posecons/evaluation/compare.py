"""Markdown tables in the layout of the paper's Table 1 from depth-evaluation JSON files."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

from ..errors import PoseconsError

# (JSON key, column header, higher is better); σ/μ is the mean over sequences of the frame scales' σ/μ.
TABLE1_COLUMNS = (
    ("scale_cv", "σ/μ", False),
    ("abs_rel", "Abs Rel", False),
    ("sq_rel", "Sq Rel", False),
    ("rmse", "RMSE", False),
    ("rmse_log", "RMSE log", False),
    ("a1", "δ<1.25", True),
    ("a2", "δ<1.25²", True),
    ("a3", "δ<1.25³", True),
)
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


def _cell(value: float | None) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:.3f}"


def table1_header() -> list[str]:
    """The two Markdown header lines of a Table-1 layout with a leading name column."""
    headers = ["Method"] + [header for _, header, _ in TABLE1_COLUMNS]
    return ["| " + " | ".join(headers) + " |", "|" + "|".join([" --- "] + [" ---: "] * len(TABLE1_COLUMNS)) + "|"]


def default_name(path: str | Path) -> str:
    """Row name for a result path: the run directory's name (also for ``<run>/eval/depth.json``), else the stem."""
    path = Path(path).resolve()
    if path.is_dir():
        return path.name
    return path.parents[1].name if path.parent.name == RUN_RESULT.parent.name else path.stem


def markdown_table(results: Sequence[dict], names: Sequence[str], bold: bool = True) -> str:
    """Table-1 layout, one row per result; with ``bold`` the best value of each column (as printed) is bold."""
    if len(names) != len(results):
        raise PoseconsError(f"{len(names)} names for {len(results)} results")
    cells = [[_cell(result.get(key)) for key, _, _ in TABLE1_COLUMNS] for result in results]
    for col, (_, _, higher_better) in enumerate(TABLE1_COLUMNS if bold else ()):
        printed = [float(row[col]) for row in cells if row[col] != "–"]
        if printed:
            best = max(printed) if higher_better else min(printed)
            for row in cells:
                if row[col] != "–" and float(row[col]) == best:
                    row[col] = f"**{row[col]}**"
    lines = table1_header() + ["| " + " | ".join([name, *row]) + " |" for name, row in zip(names, cells)]
    notes = [
        f"- {name}: {checkpoint_note(result['checkpoint'])}"
        for name, result in zip(names, results)
        if "checkpoint" in result
    ]
    return "\n".join(lines + ([""] + notes if notes else [])) + "\n"


def checkpoint_note(info: dict) -> str:
    """One line naming the evaluated weights and how they were chosen (``describe_checkpoint``)."""
    step = f", step {info['step']}" if info.get("step") is not None else ""
    return (
        f"{Path(info['file']).name}{step}; selected by: {info['selected_by']}; "
        f"initialisation: {info.get('initialisation', 'not recorded')}; weights: {info.get('weights', 'not recorded')}"
    )
