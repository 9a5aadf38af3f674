"""The one way posecons writes files, and the checks of the paths it reads and writes.

* Every file appears complete or not at all: it is written under a temporary name beside its
  target, synced to disk and renamed at the end, so an error, a kill or a crash of the machine
  never leaves a half-written file.
* Permissions follow the user's umask (temporary files and folders are created 0600/0700 by
  the standard library, so they are widened to what a plain ``open``/``mkdir`` would give).
* Nothing is deleted that posecons did not write: an output folder records the files it holds in
  a manifest, and only the files listed there are ever replaced or removed.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from .errors import PoseconsError

MANIFEST = ".posecons-outputs.json"  # in an output folder: the files posecons wrote there
# What tempfile.mkstemp makes of atomic_file's prefix ".<stem>." and the target's suffix.
_TEMPORARY = re.compile(r"\.[^/]+\.[a-z0-9_]{8}(\.\w+)?")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def make_dirs(path: str | Path) -> list[Path]:
    """Create ``path`` and its missing parents; return the folders created, outermost first."""
    path = Path(path)
    missing = [p for p in [path, *path.parents] if not p.exists()][::-1]
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise PoseconsError(f"{path}: cannot create this folder ({exc.strerror or exc})") from exc
    return missing


def check_writable(path: str | Path, folder: bool = False) -> Path:
    """Fail before the work, not after it, when ``path`` (a file, or a ``folder``) cannot be written:
    it is of the other kind, or its nearest existing parent is a file or not writable."""
    path = Path(path)
    if path.exists() and path.is_dir() != folder:
        raise PoseconsError(f"{path}: exists and is {'not a folder' if folder else 'a folder; give a file name'}")
    anchor = path if folder and path.exists() else next(p for p in path.parents if p.exists())
    if not anchor.is_dir():
        raise PoseconsError(f"{path}: cannot be created, {anchor} is a file")
    if not os.access(anchor, os.W_OK | os.X_OK):
        raise PoseconsError(f"{path}: no permission to write in {anchor}")
    return path


def require_file(path: Path, what: str) -> Path:
    """Return ``path`` if it is a file, else raise naming it and what it should have been."""
    if not path.is_file():
        raise PoseconsError(f"{path}: {what} not found")
    return path


def remove_empty(folders: list[Path]) -> None:
    """Remove ``folders`` (innermost first) that are still empty: undo :func:`make_dirs` after a failure."""
    for folder in reversed(folders):
        with contextlib.suppress(OSError):
            folder.rmdir()


@contextlib.contextmanager
def atomic_file(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path (same suffix) in ``path``'s folder that replaces ``path`` on success only."""
    path = Path(path)
    created = make_dirs(path.parent)
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    except OSError as exc:
        remove_empty(created)
        raise PoseconsError(f"{path}: cannot write here ({exc.strerror or exc})") from exc
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        # On disk before and after the rename: else a crash of the machine can leave an empty file.
        _fsync(tmp)
        os.replace(tmp, path)
        _fsync(path.parent)
    except BaseException:
        tmp.unlink(missing_ok=True)
        remove_empty(created)
        raise


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def keep_copy(source: str | Path, target: str | Path) -> None:
    """Make ``target`` a second name of ``source``'s file (a hard link, or a copy where the
    filesystem has none), atomically and on disk: ``source`` can then be replaced."""
    with atomic_file(target) as tmp:
        tmp.unlink()
        try:
            os.link(source, tmp)
        except OSError:
            shutil.copyfile(source, tmp)


def remove_temporaries(folder: str | Path) -> list[Path]:
    """Delete the temporary files :func:`atomic_file` left in ``folder`` when its process was killed
    (SIGKILL gives it no chance to clean up). Only for folders whose files are all posecons's own."""
    stale = [p for p in Path(folder).glob(".*") if p.is_file() and _TEMPORARY.fullmatch(p.name)]
    for path in stale:
        path.unlink()
    return stale


def atomic_write(path: str | Path, write: Callable[[Path], Any]) -> None:
    """Call ``write(tmp_path)``, then rename the result onto ``path``."""
    with atomic_file(path) as tmp:
        write(tmp)


def write_text(path: str | Path, text: str) -> None:
    atomic_write(path, lambda tmp: tmp.write_text(text))


def _strict(value: Any) -> Any:
    """NaN/inf → None: strict JSON readers reject NaN."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    return value


def write_json(path: str | Path, data: Any) -> None:
    """Indented strict JSON (non-finite numbers written as null)."""
    write_text(path, json.dumps(_strict(data), indent=2) + "\n")


def append_record(path: str | Path, record: dict[str, Any], key: str = "step") -> None:
    """Add ``record`` as the last line of a JSON-lines file, dropping earlier lines whose ``key`` is
    not below ``record[key]`` — the rows a resumed run repeats — so no row appears twice."""
    path = Path(path)
    lines = path.read_text().splitlines() if path.is_file() else []
    kept = [line for line in lines if line.strip() and json.loads(line).get(key, -math.inf) < record[key]]
    write_text(path, "".join(line + "\n" for line in kept + [json.dumps(_strict(record))]))


def _files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file() or p.is_symlink())


def _read_manifest(out: Path) -> set[str] | None:
    try:
        return set(json.loads((out / MANIFEST).read_text()))
    except (OSError, ValueError, TypeError):
        return None


@contextlib.contextmanager
def output_dir(out: str | Path) -> Iterator[Path]:
    """Yield an empty staging folder; on success its files appear in ``out``, on error nothing changes.

    ``out`` may be missing (it is then created whole, by one rename), an empty folder, or a folder
    that an earlier posecons command wrote: the files its manifest lists are replaced or, if the
    new output lacks them, removed; everything else in it is left alone. A folder holding other
    files, or a name the new output needs that posecons did not write, is refused before any file
    moves. Missing parent folders that were created are removed again on error.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise PoseconsError(f"{out}: output path exists and is not a folder")
    fresh = not out.exists()
    if not fresh and any(out.iterdir()) and _read_manifest(out) is None:
        raise PoseconsError(
            f"{out}: output folder is not empty and holds files posecons did not write; choose a new or empty folder"
        )
    created = make_dirs(out.parent) if fresh else []
    try:
        staging = Path(
            tempfile.mkdtemp(prefix=f".{out.name}.partial-" if fresh else ".partial-", dir=out.parent if fresh else out)
        )
    except OSError as exc:
        remove_empty(created)
        raise PoseconsError(f"{out}: cannot write here ({exc.strerror or exc})") from exc
    try:
        yield staging
        new = _files(staging)
        (staging / MANIFEST).write_text(json.dumps(new, indent=1))
        os.chmod(staging, 0o777 & ~_umask())
        if fresh:
            os.replace(staging, out)
        else:
            _merge(staging, out, new)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        remove_empty(created)
        raise


def _merge(staging: Path, out: Path, new: list[str]) -> None:
    """Move the staged files into an existing ``out``, replacing only files of its manifest."""
    old = _read_manifest(out) or set()
    foreign = [name for name in new if (out / name).exists() and name not in old]
    if foreign:
        raise PoseconsError(
            f"{out / foreign[0]}: exists and was not written by posecons; "
            "refusing to replace it (choose a new or empty folder)"
        )
    for name in sorted(old - set(new)):  # stale outputs of the earlier run
        with contextlib.suppress(FileNotFoundError):
            (out / name).unlink()
    remove_empty(sorted({out / p for name in old - set(new) for p in Path(name).parents if str(p) != "."}))
    for name in new + [MANIFEST]:
        target = out / name
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / name, target)
    shutil.rmtree(staging)
