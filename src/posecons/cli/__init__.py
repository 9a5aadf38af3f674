"""`posecons` command line: a thin layer over the library.

One module per area registers its sub-commands through ``register(subparsers)``; the library never
imports this package. The area modules import the heavy libraries (torch, matplotlib, av, onnx) inside
the commands only, so ``--help``, ``--version`` and usage errors answer at once.
"""

from __future__ import annotations

import argparse
import signal
import sys

from .. import __version__
from ..errors import PoseconsError
from . import data, evaluation, inference, study, training
from .arguments import Parser


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="posecons", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"posecons {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=Parser)
    for area in (data, training, evaluation, inference, study):  # the order of `posecons --help`
        area.register(sub)
    return parser


def _message(exc: PoseconsError) -> str:
    """The error's one line; one re-raised by a DataLoader worker carries the worker's traceback."""
    text = str(exc)
    if text.startswith(f"Caught {type(exc).__name__} in DataLoader worker"):
        text = text.rstrip().splitlines()[-1].split(f"{type(exc).__name__}: ", 1)[-1]
    return text


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    args.argv = argv  # what a command that re-executes itself (train --devices N) passes on
    try:
        return int(args.func(args) or 0)
    except PoseconsError as exc:
        print(f"posecons {args.command}: error: {_message(exc)}", file=sys.stderr)
        return getattr(exc, "exit_code", 2)
    except KeyboardInterrupt:  # Ctrl-C outside a training loop (which handles it itself): no traceback
        print(f"posecons {args.command}: interrupted", file=sys.stderr)
        return 128 + signal.SIGINT
