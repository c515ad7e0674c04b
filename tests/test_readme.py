"""The README stays true: its quick start's test command is what CI runs and its run command
names a real subcommand and scenario; its Python snippets (pymavlink, MAVSDK's native
binding, mavsdk_grpc) run as written against ``tuav-sitl up`` in a private network
namespace (tests/netns/readme_session.py)."""

import json
import re
import shlex
from pathlib import Path

import pytest
from netns_util import netns_available, run_session

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


# ----- the README's Python snippets, run as written against `tuav-sitl up`

needs_netns = pytest.mark.skipif(not netns_available(),
                                 reason="needs root (unshare) for a private network namespace")


@pytest.fixture(scope="module")
def snippets(tmp_path_factory) -> dict:
    pytest.importorskip("mavsdk.asyncio", reason="MAVSDK's native binding is a test extra")
    pytest.importorskip("mavsdk_grpc", reason="MAVSDK-Python (mavsdk-grpc) is a test extra")
    return run_session("tests.netns.readme_session", str(tmp_path_factory.mktemp("readme")),
                       timeout_s=900)


def test_readme_has_the_three_snippets_the_session_runs():
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    assert len(blocks) == 3
    assert "from pymavlink import mavutil" in blocks[0]
    assert "from mavsdk.asyncio import" in blocks[1]
    assert "import mavsdk_grpc as mavsdk" in blocks[2]


def _failure(out: dict) -> str:
    """A snippet's failure as the assertion says it: its output, up's, the processes' logs."""
    logs = "".join(f"\n--- {name}\n{text}" for name, text in out.get("logs", {}).items())
    return out["stdout"] + out["stderr"] + "\n--- up\n" + out["up_stderr"] + logs


@needs_netns
def test_pymavlink_snippet_addresses_the_autopilot_on_every_connection(snippets):
    """The winch (1/169) beats on the same link: the snippet must lock on component 1 and
    so get the copter's mode map (GUIDED = 4), ten connections out of ten."""
    heads = snippets["pymavlink"]["heads"]
    for h in heads:
        assert h["rc"] == 0, h["stderr"]
        target_system, target_component, modes = json.loads(h["stdout"].splitlines()[-1])
        assert (target_system, target_component) == (1, 1)
        assert dict(modes)["GUIDED"] == 4 and dict(modes)["RTL"] == 6


@needs_netns
def test_pymavlink_snippet_takes_off_flies_and_reads_the_winch(snippets):
    full = snippets["pymavlink"]["full"]
    assert full["rc"] == 0, _failure({**full, "up_stderr": snippets["pymavlink"]["up_stderr"],
                                      "logs": snippets["pymavlink"].get("logs", {})})
    m = re.search(r"tether paid out: ([\d.]+) m, tension ([\d.-]+) kg", full["stdout"])
    assert m is not None
    # just after the climb to 10 m beside the winder (2 m east): about the distance, paid
    # out as the vehicle climbed (the report can lag the climb by a few decimetres)
    assert 9.0 < float(m.group(1)) < 20.0
    assert snippets["pymavlink"]["up_rc"] == 0 and snippets["pymavlink"]["left"] == []


@needs_netns
def test_mavsdk_native_snippet_sets_rtl_altitude_and_finishes_its_mission(snippets):
    out = snippets["native"]
    assert out["rc"] == 0, _failure(out)
    assert "RTL altitude: 12.0 m" in out["stdout"]
    assert "mission finished" in out["stdout"]
    assert "Mission: complete" in out["stderr"]       # MAVSDK's log of the STATUSTEXT
    assert out["up_rc"] == 0 and out["left"] == []


@needs_netns
def test_mavsdk_grpc_snippet_flies_its_mission_to_the_end(snippets):
    out = snippets["grpc"]
    assert out["rc"] == 0, _failure(out)
    assert "mission finished" in out["stdout"]
    assert out["up_rc"] == 0 and out["left"] == []
