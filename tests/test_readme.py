"""The README's quick start stays true: its test command is what CI runs, and its run
command names a real subcommand and scenario."""

import re
import shlex
from pathlib import Path

from tuav_sitl.cli import build_parser
from tuav_sitl.scenario import shipped_scenarios

ROOT = Path(__file__).resolve().parents[1]


def _code_blocks(text: str) -> list[str]:
    return re.findall(r"```sh\n(.*?)```", text, flags=re.S)


def test_quick_start_has_two_commands_and_ci_runs_the_test_one():
    readme = (ROOT / "README.md").read_text()
    quick = readme.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    blocks = [b.strip() for b in _code_blocks(quick)]
    assert len(blocks) == 2
    run_cmd, test_cmd = blocks
    assert test_cmd in (ROOT / ".ci" / "run").read_text()
    assert "pytest" in test_cmd
    tool_args = shlex.split(run_cmd.split("&&", 1)[1])
    assert tool_args[0] == "tuav-sitl"
    args = build_parser().parse_args(tool_args[1:])
    if args.command == "run":
        assert args.scenario in shipped_scenarios()
