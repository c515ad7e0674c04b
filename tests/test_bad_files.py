"""Bad input files get a clear error and cost nothing: the shipped scenario, sweep and fault
files, mutated by hypothesis, either load (and a scenario then runs) or are refused with a
:class:`ParameterError` that names the file, the line and the field; the command line turns
the refusal into exit code 2 and that one message; a mission file's error names its line.

The independent truth for "the line" is the mutation itself: the test knows which line it
broke."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sitl.faults import FaultsFile
from tuav_sitl.cli import main
from tuav_sitl.scenario import load_scenario, shipped_scenarios
from tuav_sitl.sweep import load_sweep, shipped_sweeps
from tuavdefs.paramspec import ParameterError, load_toml, toml_line

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = sorted(shipped_scenarios().values())
SWEEPS = sorted(shipped_sweeps().values())
FAULT_FILES = [p for p in SCENARIOS if "[[faults]]" in p.read_text()]

#: Values a hand-edited file may put where another was: wrong types, out of range, odd.
BAD_VALUES = ['"x"', '""', "-1", "0", "-0.0", "1e308", "-1e308", "nan", "inf", "-inf",
              "true", "false", "[]", "[1, 2]", '["a"]', "{}", "{ a = 1 }", "99999999999",
              "1e-300", "0.5", "2", '"lumped"', '"catenary"', '"NAV_WAYPOINT"']

#: A ``key = value`` line of a TOML file (not a header, comment or continuation).
_KEY_LINE = re.compile(r"^\s*([A-Za-z0-9_-]+)\s*=\s*\S")


def _key_lines(text: str) -> list[int]:
    """0-based indices of the lines that set one bare key."""
    return [i for i, ln in enumerate(text.splitlines()) if _KEY_LINE.match(ln)]


@st.composite
def mutations(draw, text: str) -> tuple[str, int | None, str]:
    """(mutated text, the 1-based line changed where a value was replaced, what was done)."""
    lines = text.splitlines()
    kind = draw(st.sampled_from(["value", "value", "value", "unknown", "drop", "truncate",
                                 "garbage", "duplicate"]))
    keyed = _key_lines(text)
    if kind in ("value", "unknown", "drop", "duplicate") and keyed:
        i = draw(st.sampled_from(keyed))
        key = _KEY_LINE.match(lines[i]).group(1)
        if kind == "value":
            lines[i] = f"{key} = {draw(st.sampled_from(BAD_VALUES))}"
            return "\n".join(lines) + "\n", i + 1, f"value of {key}"
        if kind == "unknown":
            lines[i] = lines[i].replace(key, key + "_typo", 1)
            return "\n".join(lines) + "\n", i + 1, f"unknown key {key}_typo"
        if kind == "drop":
            del lines[i]
            return "\n".join(lines) + "\n", None, f"dropped {key}"
        lines.insert(i, lines[i])
        return "\n".join(lines) + "\n", i + 2, f"duplicated {key}"
    if kind == "garbage":
        i = draw(st.integers(0, len(lines)))
        lines.insert(i, draw(st.sampled_from(["%%%", "= 3", "[unclosed", "x = ", "[[]]"])))
        return "\n".join(lines) + "\n", i + 1, "garbage"
    cut = draw(st.integers(0, len(text)))
    return text[:cut], None, "truncated"


def _check_refusal(exc: ParameterError, path: Path, line: int | None, what: str) -> None:
    """The refusal names the file; the line where the mutation put a bad value or key (or
    at least some line); the field."""
    assert exc.source == str(path), (what, str(exc))
    assert exc.field and exc.reason, (what, str(exc))
    if line is not None and exc.field != "(syntax)" and not what.startswith("duplicated"):
        key = what.split()[-1]
        if exc.field.rsplit(".", 1)[-1].split("[")[0] == key:
            assert exc.line == line, (what, line, str(exc))
    if exc.field == "(syntax)" and "end of document" not in exc.reason:
        assert exc.line is not None, (what, str(exc))
    assert str(exc).startswith(f"{path}:"), str(exc)


_SLOW = settings(max_examples=30, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.function_scoped_fixture,
                                        HealthCheck.too_slow])


@pytest.mark.parametrize("source", SCENARIOS, ids=lambda p: p.stem)
@given(data=st.data())
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
def test_a_mutated_scenario_loads_or_names_file_line_and_field(source, data, tmp_path):
    text = source.read_text()
    mutated, line, what = data.draw(mutations(text))
    path = tmp_path / source.name
    path.write_text(mutated)
    try:
        load_scenario(str(path))
    except ParameterError as exc:
        _check_refusal(exc, path, line, what)


@pytest.mark.parametrize("source", SWEEPS, ids=lambda p: p.stem)
@given(data=st.data())
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
def test_a_mutated_sweep_loads_or_names_file_line_and_field(source, data, tmp_path):
    mutated, line, what = data.draw(mutations(source.read_text()))
    path = tmp_path / source.name
    path.write_text(mutated)
    # its scenario by name (the shipped one), as a sweep file beside no scenario file says
    try:
        load_sweep(path)
    except ParameterError as exc:
        if exc.source is None and "no such scenario" in exc.reason:
            return   # the mutation renamed the scenario: refused by name, no line to give
        _check_refusal(exc, path, line, what)


@pytest.mark.parametrize("source", FAULT_FILES, ids=lambda p: p.stem)
@given(data=st.data())
@_SLOW
def test_a_mutated_fault_table_loads_or_names_file_line_and_field(source, data, tmp_path):
    # the [[faults]] tables of a shipped scenario, alone in a --faults file
    text = source.read_text()
    faults = text[text.index("[[faults]]"):]
    faults = "\n".join(ln for ln in faults.splitlines()
                       if not ln.startswith("[") or ln.startswith("[[faults]]"))
    mutated, line, what = data.draw(mutations(faults))
    path = tmp_path / "faults.toml"
    path.write_text(mutated)
    try:
        load_toml(FaultsFile, path)
    except ParameterError as exc:
        _check_refusal(exc, path, line, what)


def test_the_command_line_exits_2_with_file_line_and_field(tmp_path, capsys):
    text = shipped_scenarios()["circle"].read_text().splitlines()
    i = next(i for i, ln in enumerate(text) if ln.startswith("duration_s"))
    text[i] = 'duration_s = "long"'
    path = tmp_path / "mine.toml"
    path.write_text("\n".join(text) + "\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / "kept.txt").write_text("a previous run's file")
    assert main(["run", str(path), "--out", str(out), "--no-figures", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"{path}:{i + 1}:" in err and "duration_s" in err and "'long'" in err
    assert len(err.strip().splitlines()) == 1
    assert (out / "kept.txt").read_text() == "a previous run's file"   # nothing lost
    assert sorted(p.name for p in out.iterdir()) == ["kept.txt"]


def test_the_command_line_names_the_line_of_a_syntax_error(tmp_path, capsys):
    path = tmp_path / "broken.toml"
    path.write_text('name = "x"\nduration_s = 3\nwind = [1, 2\n[plant]\n')
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert re.search(rf"{re.escape(str(path))}:[34]: ", err), err
    assert not (tmp_path / "o").exists()


def test_a_mission_file_error_names_its_line(tmp_path):
    from companion.mission_file import MissionFileError, parse

    good = (ROOT / "tests" / "data").glob("*.waypoints")
    text = next(iter(sorted(good)), None)
    body = (text.read_text() if text is not None else
            "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47.0\t8.0\t400\t1\n"
            "1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t10\t1\n")
    lines = body.splitlines()
    lines.insert(2, "2\t0\t3\tsixteen\t0\t0\t0\t0\t0\t0\t10\t1")
    with pytest.raises(MissionFileError) as info:
        parse("\n".join(lines) + "\n", source="m.waypoints")
    assert "line 3" in str(info.value) and "m.waypoints" in str(info.value)


@pytest.mark.parametrize(("text", "keys", "line"), [
    ("a = 1\nb = 2\n", ("b",), 2),
    ("a = 1\n[t]\nb = 2\n", ("t", "b"), 3),
    ("a = 1\n[t]\nb = 2\n", ("t", "c"), 2),                 # an absent key: its table
    ("[[m]]\nx = 1\n[[m]]\nx = 2\n", ("m[1]", "x"), 4),     # arrays of tables, by index
    ("[[m]]\nx = 1\n[m.sub]\ny = 3\n", ("m[0]", "sub", "y"), 4),
    ("p = [1.0, 2.0, 3.0]\n", ("p[2]",), 1),                # a scalar array's element
    ("t.u = 5\n", ("t", "u"), 1),                           # a dotted key
    ('"q k" = 5\n', ("q k",), 1),                           # a quoted key
    ("a = 1\n", ("z",), None),
])
def test_toml_line_finds_the_line_a_key_is_set_on(text, keys, line):
    assert toml_line(text, keys) == line


@given(data=st.data())
@settings(max_examples=10, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
def test_a_mutated_scenario_that_loads_runs_or_is_refused_by_field(data, tmp_path):
    """What loads must run (here its first 0.1 s) or be refused by a ParameterError naming
    the field (a plant the loader cannot judge, e.g. a line too light for its segments):
    no other exception."""
    from tuav_sitl.offline import run_scenario

    source = data.draw(st.sampled_from(SCENARIOS))
    mutated, _, what = data.draw(mutations(source.read_text()).filter(
        lambda m: m[2].startswith("value")))
    path = tmp_path / source.name
    path.write_text(mutated)
    try:
        sc = load_scenario(str(path))
    except ParameterError:
        return
    try:
        run_scenario(sc.replace(duration_s=0.1, metrics_after_s=0.0), None, progress=None)
    except ParameterError as exc:
        assert exc.field and exc.reason, (what, str(exc))


# ----- parameter files (.parm) and fault files through `tuav-sitl up`

def _default_parm() -> str:
    """A .parm file of every companion parameter at its default, as MAVProxy saves one."""
    from companion.gains import FlightControlParams
    from companion.navigation import NavigationParams
    from companion.param_names import build_defs

    defs = build_defs(FlightControlParams(), NavigationParams(), lambda _g: None,
                      lambda _n: None, lambda: 1, lambda _v: None)
    return "".join(f"{d.name},{d.get():.9g}\n" for d in defs)


@given(data=st.data())
@settings(max_examples=40, deadline=None, derandomize=True)
def test_a_mutated_parm_file_names_the_line_it_refuses(data):
    from companion.param_names import check_parm_text

    lines = _default_parm().splitlines()
    assert not check_parm_text("\n".join(lines), "p.parm")   # the defaults all apply
    i = data.draw(st.integers(0, len(lines) - 1))
    name = lines[i].split(",")[0]
    kind = data.draw(st.sampled_from(["value", "name", "garbage"]))
    if kind == "value":
        lines[i] = f"{name},{data.draw(st.sampled_from(['nan', 'inf', '-1e30', '1e30', 'x', '']))}"
    elif kind == "name":
        lines[i] = f"{name}X,1"
    else:
        lines[i] = data.draw(st.sampled_from(["%%%", "A B C", ",,", "\x00\x01"]))
    problems = check_parm_text("\n".join(lines), "p.parm")
    assert all(p.startswith("p.parm:") for p in problems), problems
    assert [int(p.split(":")[1]) for p in problems] in ([], [i + 1]), problems
    if kind in ("name", "garbage") or lines[i].endswith((",nan", ",inf", ",x", ",")):
        assert problems, lines[i]   # a value no parameter can take is always refused


def test_up_refuses_a_bad_parm_or_fault_file_before_it_makes_anything(tmp_path, capsys):
    parm = tmp_path / "bad.parm"
    parm.write_text(_default_parm() + "WPNAV_SPEED,nan\nNOT_A_PARAM 3\n")
    n = len(_default_parm().splitlines())
    logdir = tmp_path / "runs"
    assert main(["up", "--parm", str(parm), "--logdir", str(logdir), "--instance", "37"]) == 2
    err = capsys.readouterr().err
    assert f"{parm}:{n + 1}: WPNAV_SPEED" in err and f"{parm}:{n + 2}: unknown" in err
    faults = tmp_path / "faults.toml"
    faults.write_text('[[faults]]\nkind = "gnss_loss"\nstart_s = 5.0\nend_s = -1.0\n')
    assert main(["up", "--faults", str(faults), "--logdir", str(logdir),
                 "--instance", "37"]) == 2
    err = capsys.readouterr().err
    assert f"{faults}:" in err and "--faults" in err
    assert not logdir.exists()
