"""The one way posecons writes files: complete or absent, the user's umask, nothing foreign deleted."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest

from posecons.errors import PoseconsError
from posecons.fileio import (
    MANIFEST,
    append_record,
    atomic_file,
    keep_copy,
    output_dir,
    remove_temporaries,
    write_json,
    write_text,
)


@pytest.fixture
def umask():
    """Run the test under umask 002 (group-writable), restoring the caller's afterwards."""
    old = os.umask(0o002)
    yield 0o002
    os.umask(old)


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_atomic_file_keeps_the_old_content_on_error(tmp_path: Path) -> None:
    target = tmp_path / "a.json"
    write_text(target, "old")
    with pytest.raises(RuntimeError), atomic_file(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["a.json"]


def test_files_and_folders_follow_the_umask(tmp_path: Path, umask: int) -> None:
    write_json(tmp_path / "new" / "m.json", {"x": float("nan")})
    assert _mode(tmp_path / "new" / "m.json") == 0o664 and _mode(tmp_path / "new") == 0o775
    assert json.loads((tmp_path / "new" / "m.json").read_text()) == {"x": None}  # strict JSON
    with output_dir(tmp_path / "out") as tmp:
        (tmp / "depth").mkdir()
        (tmp / "depth" / "0.txt").write_text("d")
    assert _mode(tmp_path / "out") == 0o775 and _mode(tmp_path / "out" / "depth") == 0o775
    assert _mode(tmp_path / "out" / "depth" / "0.txt") == 0o664


def test_output_dir_error_leaves_nothing_not_even_new_parents(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError), output_dir(tmp_path / "a" / "b" / "out") as tmp:
        (tmp / "x").write_text("x")
        raise RuntimeError
    assert list(tmp_path.iterdir()) == []


def test_output_dir_refuses_a_foreign_folder_and_changes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / "depth").mkdir(parents=True)
    (out / "depth" / "notes.txt").write_text("mine")
    before = _tree(out)
    with pytest.raises(PoseconsError, match="not empty and holds files posecons did not write"):
        with output_dir(out) as tmp:
            (tmp / "depth").mkdir()
    assert _tree(out) == before and sorted(p.name for p in out.iterdir()) == ["depth"]


def test_rerun_replaces_only_its_own_files(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with output_dir(out) as tmp:
        (tmp / "depth").mkdir()
        for name in ("0", "1"):
            (tmp / "depth" / f"{name}.npy").write_text(f"old {name}")
    (out / "depth" / "notes.txt").write_text("the user's")  # added by the user between runs
    with output_dir(out) as tmp:
        (tmp / "depth").mkdir()
        (tmp / "depth" / "0.npy").write_text("new 0")
    assert _tree(out) == {
        MANIFEST: (out / MANIFEST).read_bytes(),
        "depth/0.npy": b"new 0",
        "depth/notes.txt": b"the user's",
    }  # the stale 1.npy of the first run is gone
    assert json.loads((out / MANIFEST).read_text()) == ["depth/0.npy"]


def test_rerun_refuses_to_replace_a_file_it_did_not_write(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with output_dir(out) as tmp:
        (tmp / "a.txt").write_text("a")
    (out / "b.txt").write_text("the user's")
    before = _tree(out)
    with pytest.raises(PoseconsError, match=r"b\.txt: exists and was not written by posecons"):
        with output_dir(out) as tmp:
            (tmp / "a.txt").write_text("a2")
            (tmp / "b.txt").write_text("b2")
    assert _tree(out) == before and not [p for p in out.iterdir() if p.name.startswith(".partial")]


def test_output_path_that_is_a_file_is_refused(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(PoseconsError, match="exists and is not a folder"), output_dir(tmp_path / "f"):
        pass
    with pytest.raises(PoseconsError, match="cannot create this folder"):
        write_text(tmp_path / "f" / "sub" / "a.txt", "x")


def test_temporaries_of_a_killed_writer_are_removed(tmp_path: Path) -> None:
    import tempfile

    fd, name = tempfile.mkstemp(prefix=".last.", suffix=".pt", dir=tmp_path)  # what atomic_file makes
    os.close(fd)
    for keep in ("last.pt", ".hidden", ".last.pt"):
        (tmp_path / keep).write_text("x")
    assert remove_temporaries(tmp_path) == [Path(name)]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".hidden", ".last.pt", "last.pt"]


def test_append_record_drops_rows_a_resume_repeats(tmp_path: Path) -> None:
    path = tmp_path / "metrics.jsonl"
    for step in (10, 20, 30, 20, 30):  # a run killed after step 30 and resumed from step 10
        append_record(path, {"step": step, "v": step})
    assert [json.loads(line)["step"] for line in path.read_text().splitlines()] == [10, 20, 30]


def test_atomic_file_syncs_the_file_before_the_rename_and_the_folder_after(tmp_path: Path, monkeypatch) -> None:
    """Without both, a crash of the machine can leave the new name on an empty file. Caught
    mutations: either ``_fsync`` call in ``atomic_file`` removed."""
    events = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: events.append(("fsync", os.fstat(fd).st_ino)) or real_fsync(fd))
    monkeypatch.setattr(os, "replace", lambda a, b: events.append(("replace",)) or real_replace(a, b))
    target = tmp_path / "new" / "last.pt"
    write_text(target, "state")
    assert events == [("fsync", target.stat().st_ino), ("replace",), ("fsync", target.parent.stat().st_ino)]


def test_keep_copy_links_where_it_can_and_survives_the_replacement_of_its_source(tmp_path: Path, monkeypatch) -> None:
    """A hard link (no copy of a large checkpoint), a copy on a filesystem without links. Caught
    mutations: always copying (the inode check); the copy fallback removed (the second round)."""

    def no_links(source, target):
        raise OSError("this filesystem has no hard links")

    source, kept = tmp_path / "last.pt", tmp_path / "last.prev.pt"
    write_text(kept, "step 0")
    for linked in (True, False):
        write_text(source, "step 1")
        keep_copy(source, kept)
        assert (kept.stat().st_ino == source.stat().st_ino) == linked
        write_text(source, "step 2")
        assert kept.read_text() == "step 1" and source.read_text() == "step 2"
        assert sorted(p.name for p in tmp_path.iterdir()) == ["last.prev.pt", "last.pt"]
        monkeypatch.setattr(os, "link", no_links)
