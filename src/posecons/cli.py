"""`posecons` command line: a thin layer over the library.

Each area registers its own sub-commands through ``register(subparsers)`` in its
``commands`` module, so the CLI file never grows with the library.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .errors import PoseconsError

COMMAND_MODULES = (
    "posecons.data.commands",
    "posecons.training.commands",
    "posecons.evaluation.commands",
    "posecons.inference.commands",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="posecons", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
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


if __name__ == "__main__":
    sys.exit(main())
