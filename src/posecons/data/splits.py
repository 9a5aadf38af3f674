"""Split files: one ``<folder> <frame> <side>`` line per sample.

Raw KITTI lines name a drive folder (``2011_09_26/2011_09_26_drive_0002_sync``), odometry lines a
sequence number (``9``). Eigen test lines pad frames to 10 digits; the frame value is what matters.
"""

from __future__ import annotations

import random
from collections.abc import Iterable, Sequence, Set
from dataclasses import dataclass
from pathlib import Path
from typing import Union

from ..errors import PoseconsError
from ..fileio import require_file, write_text

BUNDLED = Path(__file__).resolve().parents[1] / "splits"
"""The standard KITTI split lists shipped with the package (origin in its NOTICE)."""
SIDES = ("l", "r")
SIDE_TO_CAMERA = {"l": 2, "r": 3}  # left / right colour camera


@dataclass(frozen=True)
class SplitLine:
    """One split entry; ``where`` is ``file:line`` for error messages."""

    folder: str
    frame: int
    side: str
    where: str = ""

    def __str__(self) -> str:
        return f"{self.folder} {self.frame} {self.side}"


def parse_split_lines(lines: Iterable[str], source: str = "<lines>") -> list[SplitLine]:
    """Parse split lines (blank lines skipped); bad field count, frame or side → error with file:line."""
    out = []
    for number, raw in enumerate(lines, start=1):
        fields = raw.split()
        if not fields:
            continue
        where = f"{source}:{number}"
        if len(fields) != 3:
            raise PoseconsError(
                f"{where}: expected '<folder> <frame> <l|r>', got {len(fields)} fields: {raw.strip()!r}"
            )
        folder, frame, side = fields
        if not frame.isdigit():
            raise PoseconsError(f"{where}: frame {frame!r} is not a non-negative integer")
        if side not in SIDES:
            raise PoseconsError(f"{where}: side {side!r} is not 'l' or 'r'")
        out.append(SplitLine(folder, int(frame), side, where))
    return out


SplitSource = Union[str, Path, Sequence[str], Sequence[SplitLine]]


def bundled_names() -> list[str]:
    return sorted(p.name for p in BUNDLED.iterdir() if p.is_dir())


def find_split_file(path: str | Path) -> Path:
    """``path`` if it is a file, else a bundled split: ``eigen/test_files.txt``, or ``eigen`` for its
    ``test_files.txt``."""
    path = Path(path)
    if path.is_file():
        return path
    bundled = BUNDLED / path
    bundled = bundled / "test_files.txt" if bundled.is_dir() else bundled
    if bundled.is_file():
        return bundled
    raise PoseconsError(
        f"{path}: split file not found (nor a bundled split: {', '.join(bundled_names())}, "
        "e.g. eigen or odom/test_files_09.txt)"
    )


def read_split(source: SplitSource) -> list[SplitLine]:
    """Read a split file (or a bundled one by name, see :func:`find_split_file`), or parse a list of
    lines / pass through a list of :class:`SplitLine`."""
    if isinstance(source, (str, Path)):
        path = find_split_file(source)
        return parse_split_lines(path.read_text().splitlines(), str(path))
    items = list(source)
    if items and isinstance(items[0], SplitLine):
        return items  # type: ignore[return-value]
    return parse_split_lines(items)  # type: ignore[arg-type]


def write_split(path: Path, lines: Iterable[SplitLine], frame_digits: int = 0) -> None:
    """Write split lines; ``frame_digits=10`` gives the eigen test style (``0000000069``)."""
    text = "".join(f"{s.folder} {s.frame:0{frame_digits}d} {s.side}\n" for s in lines)
    write_text(path, text)


def read_static_frames(path: Path) -> set[tuple[str, int]]:
    """SfMLearner ``static_frames.txt`` (``<date> <drive> <frame>``) → {(drive, frame)}."""
    path = require_file(Path(path), "static frames file")
    out = set()
    for number, raw in enumerate(path.read_text().splitlines(), start=1):
        fields = raw.split()
        if not fields:
            continue
        if len(fields) != 3 or not fields[2].isdigit():
            raise PoseconsError(f"{path}:{number}: expected '<date> <drive> <frame>', got {raw.strip()!r}")
        out.add((fields[1], int(fields[2])))
    return out


def read_test_scenes(path: Path) -> set[str]:
    """``test_scenes_eigen.txt`` (``2011_09_26_drive_0117``) → set of drive names without ``_sync``."""
    path = require_file(Path(path), "test scenes file")
    return {line.strip() for line in path.read_text().splitlines() if line.strip()}


def build_split(
    data_path: Path,
    static_frames: Set[tuple[str, int]] = frozenset(),
    test_scenes: Set[str] = frozenset(),
    val_fraction: float = 0.1,
    seed: int = 0,
    img_ext: str = ".png",
) -> tuple[list[SplitLine], list[SplitLine]]:
    """Zhou-style train/val lines from a raw tree: every image (left and right camera) whose
    neighbours −1/+1 exist, minus static frames and test drives; a random ``val_fraction`` of the
    lines goes to validation. Returns (train, val); folders are ``<date>/<date>_drive_NNNN_sync``.
    """
    data_path = Path(data_path)
    lines = []
    for drive_dir in sorted(data_path.glob("*/*_drive_*_sync")):
        drive = drive_dir.name
        if drive.removesuffix("_sync") in test_scenes:
            continue
        folder = f"{drive_dir.parent.name}/{drive}"
        for side, cam in zip(SIDES, ("image_02", "image_03")):
            frames = {int(p.stem) for p in (drive_dir / cam / "data").glob(f"*{img_ext}") if p.stem.isdigit()}
            for frame in sorted(frames):
                if frame - 1 in frames and frame + 1 in frames and (drive, frame) not in static_frames:
                    lines.append(SplitLine(folder, frame, side))
    if not lines:
        raise PoseconsError(
            f"{data_path}: no usable frames found (expected <date>/<drive>_sync/image_02/data/*{img_ext})"
        )
    rng = random.Random(seed)
    rng.shuffle(lines)
    n_val = int(round(len(lines) * val_fraction))
    return lines[n_val:], lines[:n_val]
