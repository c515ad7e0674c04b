"""The paper's length law for a stack a test starts by hand: the files that give its ground
station the paper's winder law (``[winder_control] law = "paper"``, L-bar followed with the
stop lead) and its companion the tether governor for a length law (``TUAV_TETH_GOV`` 1),
as the sessions that check L-bar and the stop lead's bound were written for; the defaults
are the tension law and governor 2 (docs/control.md §3, §8). The plant's truth line is
each session's to name (``python -m sitl`` flies the catenary unless its parameters say
otherwise; ``tuav-sitl up`` the lumped line unless ``--tether-model``)."""

from __future__ import annotations

from pathlib import Path

#: ``python -m groundstation --control`` / ``tuav-sitl up --ground-params``
CONTROL_TOML = '[winder_control]\nlaw = "paper"\n'
#: ``python -m companion --nav``
NAV_TOML = "tether_governor = 1\n"
#: ``tuav-sitl up --parm``
PARM = "TUAV_TETH_GOV 1\n"


def write(directory: Path) -> dict[str, Path]:
    """Write the three files into ``directory``: {"control", "nav", "parm"} -> path."""
    directory.mkdir(parents=True, exist_ok=True)
    files = {"control": (directory / "paper_law.toml", CONTROL_TOML),
             "nav": (directory / "length_governor.toml", NAV_TOML),
             "parm": (directory / "length_governor.parm", PARM)}
    for path, text in files.values():
        path.write_text(text)
    return {k: p for k, (p, _) in files.items()}
