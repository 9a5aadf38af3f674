"""First contact: --help, --version and usage errors answer without loading heavy libraries, and every
option's help shows its default."""

import argparse
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
