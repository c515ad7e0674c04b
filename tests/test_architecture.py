"""The import rule of docs/architecture.md: the three process packages never import each
other, and the shared package imports none of them."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROCESS_PACKAGES = {"sitl", "companion", "groundstation"}
FORBIDDEN = {
    "sitl": {"companion", "groundstation", "tuav_sitl"},
    "companion": {"sitl", "groundstation", "tuav_sitl"},
    "groundstation": {"sitl", "companion", "tuav_sitl"},
    "tuavdefs": {"sitl", "companion", "groundstation", "tuav_sitl"},
}


def _imported_top_levels(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_import_rule(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"{package} has no modules"
    for f in files:
        bad = _imported_top_levels(f) & FORBIDDEN[package]
        assert not bad, f"{f.relative_to(ROOT)} imports {sorted(bad)}"


def test_tests_do_not_import_benchmarks():
    """The test suite runs the benchmarks only as a command (``tuav-sitl bench``); what it
    shares with them (the network-namespace helper, the schedulings) is in ``tuav_sitl``."""
    for f in sorted((ROOT / "tests").rglob("*.py")):
        assert "benchmarks" not in _imported_top_levels(f), \
            f"{f.relative_to(ROOT)} imports benchmarks"


def test_the_checker_sees_imports(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("import os\nfrom companion.x import y\nfrom . import z\n")
    assert _imported_top_levels(f) == {"os", "companion"}
