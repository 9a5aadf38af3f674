"""The run folder as a place one process trains in at a time: its lock (:func:`run_in_progress` tells
a study which runs another process holds), the checks before training (writable; no earlier run
unless resumed), the removal of what a failed first attempt wrote, and the crash record it leaves
instead (``RUN/crash.log`` and ``RUN/tb/``) when it failed in training. Kept apart from the trainer
because it is about files, not training: which of them are this attempt's, and which stay."""

from __future__ import annotations

import contextlib
import shutil
import sys
import tempfile
import traceback
from pathlib import Path

from filelock import FileLock, Timeout

from ..errors import PoseconsError
from ..fileio import remove_empty, write_text

RUN_LOCK = ".lock"
CRASH_LOG = "crash.log"
CRASH_RECORD = (CRASH_LOG, "tb")  # what a run that crashed before its first checkpoint leaves


@contextlib.contextmanager
def hold_run_dir(out: Path):
    """Hold ``out``'s lock while a process trains there: a second process on the same run directory
    (two study sittings picking the same run, a repeated command) stops at once instead of writing
    over the first one's checkpoints and logs. A folder that was new or empty when the lock was
    taken holds only this process's files: a failure before the first checkpoint removes them
    (yields whether it was)."""
    created = _writable_dir(out)
    lock = FileLock(out / RUN_LOCK, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        raise PoseconsError(f"{out}: another process is training this run; wait for it or stop it") from None
    left = {p.name for p in out.iterdir()} - {RUN_LOCK}
    fresh, discard = not left or (CRASH_LOG in left and left <= set(CRASH_RECORD)), False
    if fresh:  # this attempt replaces the crash record of an earlier one
        _remove_all_but(out, {RUN_LOCK})
    try:
        yield fresh
    except BaseException:
        discard = fresh and not (out / "checkpoints" / "last.pt").exists()
        if discard:  # a run that crashed in training keeps its record; the lock goes last, while held
            _remove_all_but(out, {RUN_LOCK, *(CRASH_RECORD if (out / CRASH_LOG).is_file() else ())})
            (out / RUN_LOCK).unlink()
        raise
    finally:
        lock.release()
        if discard:
            remove_empty(created)


def run_in_progress(out: Path) -> bool:
    """Whether another process is training in ``out`` now (holds its lock): a study skips that run."""
    if not (out / RUN_LOCK).is_file():
        return False
    try:
        with FileLock(out / RUN_LOCK, timeout=0):
            return False
    except Timeout:
        return True


def _writable_dir(out: Path) -> list[Path]:
    """Make ``out`` if needed and return the folders made, outermost first; an unwritable one is an
    error naming it."""
    created = [p for p in [out, *out.parents] if not p.exists()][::-1]
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):  # a probe of its own: other processes may probe at once
            pass
    except OSError as exc:
        raise PoseconsError(f"run directory {out} is not writable: {exc.strerror}") from exc
    return created


def prepare_run_dir(out: Path, resume: bool) -> None:
    """Check ``out`` before a run starts there: writable, and holding no earlier run unless resumed."""
    _writable_dir(out)
    if not resume and (out / "checkpoints" / "last.pt").exists():
        raise PoseconsError(f"{out} already holds a run: pass --resume to continue it, or choose a new --out")


def _remove_all_but(out: Path, keep: set[str]) -> None:
    """Remove the entries of a run folder whose files are all posecons's own, but those named ``keep``."""
    for entry in out.iterdir():
        if entry.name in keep:
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()


def write_crash_record(out: Path, step: int, exc: BaseException, writer) -> None:
    """``RUN/crash.log`` (the error and its traceback) beside ``RUN/tb/``, flushed by closing the
    run's TensorBoard ``writer`` (None on no log): what stays of a run that crashed before its
    first checkpoint, whose other files are removed."""
    if writer:
        writer.close()
    error = "".join(traceback.format_exception_only(exc)).strip()
    write_text(
        out / CRASH_LOG,
        f"training crashed at step {step}: {error}\n\n" + "".join(traceback.format_exception(exc)),
    )
    print(
        f"{out}: the run crashed at step {step}, before its first checkpoint; the error is in "
        f"{out / CRASH_LOG}, the TensorBoard log in {out / 'tb'}",
        file=sys.stderr,
    )
