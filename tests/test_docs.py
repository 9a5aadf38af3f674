"""The commands docs/kitti.md gives users exist, with its options, option values, presets and config keys."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from posecons.cli import build_parser
from posecons.config import load_config, resolve_preset
from posecons.data.splits import find_split_file

DOC = Path(__file__).resolve().parents[1] / "docs" / "kitti.md"


def _expand(command: str, loops: dict[str, list[str]]) -> list[str]:
    """One command per value of each shell loop variable (``for p in a b; do … $p …``) it uses."""
    for var, values in loops.items():
        if f"${var}" in command:
            return [c for v in values for c in _expand(command.replace(f"${var}", v), loops)]
    return [command]


def doc_commands(text: str) -> list[list[str]]:
    """``[subcommand, arg, …]`` of every ``posecons …`` call in the page's bash blocks and inline code."""
    found = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        block = block.replace("\\\n", " ")
        loops = {var: values.split() for var, values in re.findall(r"for (\w+) in ([^;]+); do", block)}
        for line in block.splitlines():
            for call in re.findall(r"\bposecons ([a-z][^;|&]*)", line):
                found += _expand(call, loops)
    found += [span.replace("\n", " ") for span in re.findall(r"`posecons ([a-z][^`]*)`", text)]
    return [shlex.split(call, comments=True) for call in found]


COMMANDS = doc_commands(DOC.read_text())


def test_every_paper_preset_has_a_train_command():
    assert {"train", "export-gt", "evaluate-depth", "evaluate-pose", "compare"} <= {c[0] for c in COMMANDS}
    presets = {c[c.index("--config") + 1] for c in COMMANDS if c[0] == "train"}
    rows = ("baseline", "identity", "forward_backward", "cycle")
    assert {f"{folder}/{row}" for folder in ("kitti", "kitti_odom") for row in rows} <= presets


@pytest.mark.parametrize("argv", COMMANDS, ids=[" ".join(c)[:60] for c in COMMANDS])
def test_each_command_option_and_value_exists(argv):
    subparsers = next(a for a in build_parser()._actions if a.choices and "train" in a.choices)
    assert argv[0] in subparsers.choices, f"no sub-command {argv[0]}"
    options = subparsers.choices[argv[0]]._option_string_actions
    overrides = []
    for i, token in enumerate(argv[1:], 1):
        if not token.startswith("--"):
            continue
        assert token in options, f"posecons {argv[0]} has no option {token}"
        value = argv[i + 1] if i + 1 < len(argv) else None
        choices = options[token].choices
        if choices is not None:
            assert value in choices, f"{token} {value}: not one of {list(choices)}"
        if token == "--set":
            overrides.append(value)
        if token == "--split-file" and "$" not in value:
            find_split_file(value)  # a bundled split name must exist
    if argv[0] == "train":
        config = argv[argv.index("--config") + 1]
        load_config(resolve_preset(config), overrides)  # the preset exists and takes the overrides


def test_every_config_override_the_page_names_is_a_valid_key():
    overrides = re.findall(r"`--set ([\w.]+=[^`\s]+)`", DOC.read_text())
    assert "data.img_ext=.jpg" in overrides and "data.calib_intrinsics=false" in overrides
    for item in overrides:
        load_config(resolve_preset("kitti/baseline"), [item])
