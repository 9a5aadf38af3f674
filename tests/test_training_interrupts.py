"""SIGINT/SIGTERM stop training cleanly with a resumable last.pt; a run that never started leaves nothing."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from posecons.checkpoint import load_checkpoint
from posecons.cli import main as cli
from tiny import TINY_MODEL

pytestmark = pytest.mark.slow
TINY = [
    *TINY_MODEL,
    "train.val_samples=2",
    "train.image_every=0",
    "train.checkpoint_every=0",
]


@pytest.fixture(scope="module")
def synth_data(make_synth) -> Path:
    return make_synth(2, 10, 192, 64, 5)


def _default_sigint() -> None:
    """Ctrl-C reaches the command as from a terminal even when the suite itself runs under nohup or as
    a background job: those start with SIGINT ignored, children inherit that, and Python keeps it so."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _sets(*extra: str) -> list[str]:
    return sum([["--set", s] for s in TINY + list(extra)], [])


def _interrupt(synth_data: Path, run: Path, signum: int) -> int:
    """Start a training run with a loader worker, send ``signum`` to its process group (as Ctrl-C does)
    once it is in its loop; check the one-line message and return the step saved in last.pt."""
    args = [
        sys.executable,
        "-m",
        "posecons.cli",
        "train",
        "--config",
        "kitti/baseline",
        "--data-path",
        str(synth_data),
        "--out",
        str(run),
        "--quiet",
        *_sets("train.max_steps=6", "train.val_every=1", "data.num_workers=1"),
    ]
    proc = subprocess.Popen(
        args,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=_default_sigint,
    )
    deadline = time.time() + 300
    while time.time() < deadline and proc.poll() is None and not (run / "metrics.jsonl").is_file():
        time.sleep(0.05)  # the first validation ran: the loop is going
    assert proc.poll() is None, proc.stderr.read()
    os.killpg(proc.pid, signum)
    err = proc.communicate(timeout=300)[1]
    assert proc.returncode == 128 + signum
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines[0].startswith(f"{signal.Signals(signum).name}: stopping after this step"), err
    assert len(lines) == 2 and "last.pt" in lines[1] and "--resume" in lines[1], err  # not one per worker
    step = load_checkpoint(run / "checkpoints" / "last.pt")["step"]
    assert 1 <= step < 6
    return step


def test_sigterm_saves_last_and_says_how_to_resume(synth_data, tmp_path):
    _interrupt(synth_data, tmp_path / "run", signal.SIGTERM)


def test_ctrl_c_then_resume_reports_the_total_time(synth_data, tmp_path):
    run = tmp_path / "run"
    _interrupt(synth_data, run, signal.SIGINT)
    assert cli(["train", "--data-path", str(synth_data), "--out", str(run), "--resume", "--quiet"]) == 0
    summary = json.loads((run / "train_summary.json").read_text())
    assert summary["steps"] == 6 and summary["minutes"] > summary["minutes_this_session"] > 0
    steps = [json.loads(line)["step"] for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert steps == list(range(1, 7))


def test_run_that_fails_before_training_leaves_no_folder(synth_data, tmp_path, capsys):
    out = tmp_path / "new" / "run"
    assert (
        cli(
            [
                "train",
                "--config",
                "kitti/baseline",
                "--data-path",
                str(synth_data),
                "--out",
                str(out),
                *_sets("train.batch_size=1000"),
            ]
        )
        == 2
    )
    assert "fewer than one batch" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # neither the run folder nor the parent it created


def test_run_that_crashes_before_its_first_checkpoint_leaves_its_error_and_tensorboard_log(
    synth_data, tmp_path, capsys, monkeypatch
):
    """A frame that fails to load at the second step: the run folder keeps crash.log and tb/ (with the
    first step's losses) and nothing else; the next attempt there replaces the record. Caught
    mutations: no crash record written; the discard not sparing it; an earlier record not cleared."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from posecons.training import trainer as trainer_module

    real, calls = trainer_module.jitter_batch, []

    def corrupt_second_batch(batch):
        calls.append(1)
        if len(calls) == 2:
            raise OSError("image file is truncated")
        return real(batch)

    monkeypatch.setattr(trainer_module, "jitter_batch", corrupt_second_batch)
    out = tmp_path / "run"
    argv = ["train", "--config", "kitti/baseline", "--data-path", str(synth_data), "--out", str(out), "--quiet"]
    argv += _sets("train.max_steps=2", "train.val_every=off", "train.log_every=1")
    with pytest.raises(OSError, match="image file is truncated"):
        cli(argv)
    assert sorted(p.name for p in out.iterdir()) == ["crash.log", "tb"]
    record = (out / "crash.log").read_text()
    assert record.startswith("training crashed at step 1: OSError: image file is truncated") and "Traceback" in record
    assert f"the error is in {out / 'crash.log'}" in capsys.readouterr().err
    events = EventAccumulator(str(out / "tb"))
    events.Reload()
    assert [e.step for e in events.Scalars("loss/total")] == [1]

    monkeypatch.setattr(trainer_module, "jitter_batch", real)
    assert cli(argv) == 0
    assert not (out / "crash.log").exists() and load_checkpoint(out / "checkpoints" / "last.pt")["step"] == 2
    assert len(list((out / "tb").iterdir())) == 1  # the crashed attempt's events are gone with its record


def test_resume_from_a_weights_only_checkpoint_is_refused(synth_data, tmp_path, capsys):
    run = tmp_path / "run"
    assert (
        cli(
            [
                "train",
                "--config",
                "kitti/baseline",
                "--data-path",
                str(synth_data),
                "--out",
                str(run),
                "--quiet",
                *_sets("train.max_steps=1", "train.val_every=1"),
            ]
        )
        == 0
    )
    (run / "checkpoints" / "best.pt").replace(run / "checkpoints" / "last.pt")
    assert cli(["train", "--data-path", str(synth_data), "--out", str(run), "--resume"]) == 2
    assert "holds no training state" in capsys.readouterr().err


def test_ctrl_c_during_synth_leaves_nothing(tmp_path):
    """Ctrl-C reaches the whole process group (parent and render workers): one line, exit 130, no output."""
    out = tmp_path / "new" / "synth"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "posecons.cli",
            "synth",
            "--out",
            str(out),
            "--drives",
            "4",
            "--frames",
            "60",
            "--width",
            "320",
            "--height",
            "96",
            "--workers",
            "2",
        ],
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=_default_sigint,
    )
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None and not list(out.parent.glob(".synth.partial-*/2020_01_01")):
        time.sleep(0.05)  # rendering has begun
    os.killpg(proc.pid, signal.SIGINT)
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == 128 + signal.SIGINT and err.strip() == "posecons synth: interrupted", err
    assert list(tmp_path.iterdir()) == []
