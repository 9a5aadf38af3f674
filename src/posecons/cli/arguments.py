"""The argument types and helpers the sub-commands share: a bad value is a usage error naming the option."""

from __future__ import annotations

import argparse
import inspect
import math
import re
from collections.abc import Callable
from pathlib import Path

from ..errors import PoseconsError
from ..fileio import check_writable


def _number(kind: type, test: Callable[[float], bool], rule: str) -> Callable[[str], float]:
    """An argparse ``type`` that accepts a finite ``kind`` (int or float) passing ``test``."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if kind is int else 'a number'}, got {text!r}"
            ) from None
        if not (math.isfinite(value) and test(value)):
            raise argparse.ArgumentTypeError(f"must be {rule}, got {text}")
        return value

    return parse


# Argument types shared by the commands: a bad number is a usage error naming the option.
positive_int = _number(int, lambda v: v >= 1, "an integer ≥ 1")
non_negative_int = _number(int, lambda v: v >= 0, "an integer ≥ 0")
positive_float = _number(float, lambda v: v > 0, "a number > 0")
non_negative_float = _number(float, lambda v: v >= 0, "a number ≥ 0")
finite_float = _number(float, lambda v: True, "a finite number")
fraction = _number(float, lambda v: 0 <= v <= 1, "a number in [0, 1]")
field_of_view = _number(float, lambda v: 1 <= v <= 170, "a field of view in degrees, 1–170")


def device_name(text: str) -> str:
    """A torch device name, checked by spelling only (availability is checked when it is used)."""
    if not re.fullmatch(r"cpu|cuda(:\d+)?|mps", text):
        raise argparse.ArgumentTypeError(f"expected cpu, cuda, cuda:N or mps, got {text!r}")
    return text


def _writable(folder: bool) -> Callable[[str], Path]:
    def parse(text: str) -> Path:
        try:
            return check_writable(Path(text), folder)
        except PoseconsError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse


# Output paths are checked when parsed, so an impossible one fails before any work is done.
output_file = _writable(folder=False)
output_folder = _writable(folder=True)


def new_output_file(text: str) -> Path:
    """An ``output_file`` that does not exist yet: for outputs that could replace a file of the user's,
    such as a trained checkpoint, which posecons never replaces (README, "Errors and interrupts")."""
    path = output_file(text)
    if path.exists():
        raise argparse.ArgumentTypeError(f"{path}: exists; give a new file name (posecons replaces no file of yours)")
    return path


def add_command(
    subparsers: argparse._SubParsersAction, name: str, func: Callable[[argparse.Namespace], int]
) -> argparse.ArgumentParser:
    """The sub-command ``name`` that runs ``func``, described by ``func``'s docstring (written for users):
    its first line is the command's line in ``posecons --help``, the rest the description of its own
    ``--help``."""
    summary, _, description = inspect.getdoc(func).partition("\n\n")
    parser = subparsers.add_parser(name, help=summary, description=description or None)
    parser.set_defaults(func=func)
    return parser


def add_overrides(parser: argparse.ArgumentParser, example: str) -> None:
    """The repeatable ``--set KEY=VALUE`` config override of the commands that build a config."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=f"{example} (repeatable)"
    )


def add_accelerator(parser: argparse.ArgumentParser) -> None:
    """The ``--accelerator`` of the commands that train (train, study)."""
    parser.add_argument(
        "--accelerator",
        choices=("auto", "cpu", "cuda"),
        default="auto",
        help="auto: CUDA when a GPU is visible, else the CPU",
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
