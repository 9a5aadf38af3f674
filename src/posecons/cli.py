"""`posecons` command line: a thin layer over the library.

Each area registers its own sub-commands through ``register(subparsers)`` in its
``commands`` module, so the CLI file never grows with the library. Those modules import the
heavy libraries (torch, matplotlib, av, onnx) inside the commands only, so ``--help``,
``--version`` and usage errors answer at once.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys

from . import __version__
from .errors import PoseconsError

COMMAND_MODULES = (
    "posecons.data.commands",
    "posecons.training.commands",
    "posecons.evaluation.commands",
    "posecons.inference.commands",
)


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's help ends with its default, unless it has none or the text already says it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        no_default = action.default is None or action.default is False or action.default == []
        if no_default or action.default is argparse.SUPPRESS or "default" in text:
            return text
        return super()._get_help_string(action)


class Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="posecons", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"posecons {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=Parser)
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:  # a real missing dependency, not an area still to come
                raise
            continue
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except PoseconsError as exc:
        print(f"posecons {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C outside a training loop (which handles it itself): no traceback
        print(f"posecons {args.command}: interrupted", file=sys.stderr)
        return 128 + signal.SIGINT


if __name__ == "__main__":
    sys.exit(main())
