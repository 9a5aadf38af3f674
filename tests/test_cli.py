"""First contact: --help, --version and usage errors answer without loading heavy libraries, and every
option's help shows its default."""

import argparse
import inspect
import subprocess
import sys

import pytest

from posecons import __version__
from posecons.cli import build_parser, main

HEAVY = ("torch", "matplotlib", "tensorboard", "av", "onnx", "onnxruntime")
PROBE = """
import contextlib, io, sys
from posecons.cli import main
for argv in (["--help"], ["--version"], ["train"], ["synth", "--drives", "0"], ["predict", "--help"]):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            main(argv)
        except SystemExit:
            pass
print(" ".join(m for m in %r if m in sys.modules))
"""


def test_help_version_and_usage_errors_load_no_heavy_library():
    out = subprocess.run([sys.executable, "-c", PROBE % (HEAVY,)], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"posecons {__version__}"


def test_the_removed_stabiliser_is_an_unknown_option(capsys):
    """predict --stabilise was removed (it raised σ/μ everywhere measured, docs/results.md): a usage error."""
    with pytest.raises(SystemExit) as exc:
        main(["predict", "--checkpoint", "m.pt", "--input", "frames", "--out", "out", "--stabilise"])
    assert exc.value.code == 2 and "unrecognized arguments: --stabilise" in capsys.readouterr().err


def test_every_option_with_a_default_shows_it():
    sub = build_parser()._subparsers._group_actions[0]
    for name, parser in sub.choices.items():
        text = parser.format_help()
        for action in parser._actions:
            if action.default is None or action.default is False or action.default in ([], argparse.SUPPRESS):
                continue
            assert "default" in (action.help or "") or f"(default: {action.default})" in " ".join(text.split()), (
                name,
                action.dest,
            )


def test_train_on_several_devices_relaunches_the_argv_given_to_main(monkeypatch, tmp_path):
    """Caught mutation: ``_launch_torchrun`` passing on ``sys.argv[1:]`` (pytest's own arguments here)."""
    from posecons.cli import training

    launched = []
    monkeypatch.setattr(training.subprocess, "call", lambda cmd: launched.append(cmd) or 0)
    monkeypatch.delenv("WORLD_SIZE", raising=False)
    argv = ["train", "--config", "kitti/cycle", "--data-path", str(tmp_path), "--out", str(tmp_path / "run")]
    argv += ["--devices", "2", "--set", "train.max_steps=1"]
    assert main(argv) == 0
    [cmd] = launched
    assert cmd[cmd.index("posecons.cli") + 1 :] == argv and "--nproc-per-node=2" in cmd


def test_each_command_is_described_by_its_function_docstring():
    """`posecons --help` lists each command with the first line of its function's docstring, and the
    command's own --help starts with the rest."""
    parser = build_parser()
    sub = parser._subparsers._group_actions[0]
    summaries = {a.dest: a.help for a in sub._choices_actions}
    for name, command in sub.choices.items():
        func = command.get_default("func")
        summary, _, description = func.__doc__.partition("\n\n")
        assert summaries[name] == summary and "\n" not in summary, name
        assert command.description == (inspect.cleandoc(description) or None), name
