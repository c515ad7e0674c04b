"""The README stays true: its quick start's test command is what CI runs and its run command
names a real subcommand and scenario; its three Python snippets (pymavlink, MAVSDK's native
binding, mavsdk_grpc) are the ones tests/test_first_contact.py runs as written against
``tuav-sitl up``, started at its banner, at every speed-up."""

import re
import shlex
from pathlib import Path

from tests.netns.readme_session import python_blocks
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


# ----- the README's Python snippets: tests/test_first_contact.py flies each as written,
# from up's banner at every speed-up


def test_readme_has_the_three_snippets_the_flights_run():
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    assert len(blocks) == 3
    assert "from pymavlink import mavutil" in blocks[0]
    assert "from mavsdk.asyncio import" in blocks[1]
    assert "import mavsdk_grpc as mavsdk" in blocks[2]
    assert python_blocks() == blocks       # what the flights run
