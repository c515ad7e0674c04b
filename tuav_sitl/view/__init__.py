"""Rerun views of the stack: a run's ``recording.rrd`` and the live view of ``tuav-sitl up``.

``rerun-sdk`` (its viewer, CLI and pyarrow: about 670 MB) is the optional extra ``view``
(``pip install -e '.[view]'``); :func:`rerun_module` imports it, with its usage analytics
turned off first, or raises :class:`ViewUnavailableError` saying how to get it. The modules:
:mod:`tuav_sitl.view.recording` (what is logged, the blueprint, a run's series into a
recording), :mod:`tuav_sitl.view.live` (the process ``up`` starts beside the stack),
:mod:`tuav_sitl.view.open` (``tuav-sitl view RUN``).
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

#: How to get rerun, for the messages of a command that needs it.
INSTALL_HINT = ("the view needs rerun-sdk, the optional extra 'view': "
                "pip install 'tuav-sitl[view]' (in a checkout: pip install -e '.[view]')")
#: The file a recording is written to in a run folder.
RECORDING_NAME = "recording.rrd"


class ViewUnavailableError(RuntimeError):
    """rerun-sdk is not installed (the message says how to install it)."""


def available() -> bool:
    """Whether rerun-sdk can be imported (without importing it)."""
    return importlib.util.find_spec("rerun") is not None


def analytics_config_path() -> Path:
    """Rerun's analytics settings (``rerun analytics disable`` writes them): the
    ``rerun/analytics.json`` of the XDG config directory."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "rerun" / "analytics.json"


def analytics_off() -> bool:
    """Turn rerun's usage analytics off, as ``rerun analytics disable`` does (the setting
    its SDK and viewer read), unless they are off already; returns whether they are off."""
    path = analytics_config_path()
    try:
        if json.loads(path.read_text()).get("analytics_enabled") is False:
            return True
    except (OSError, ValueError, AttributeError):
        pass
    try:
        subprocess.run([sys.executable, "-m", "rerun_cli", "analytics", "disable"],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=30,
                       check=False)
    except (OSError, subprocess.TimeoutExpired):
        return False
    try:
        return json.loads(path.read_text()).get("analytics_enabled") is False
    except (OSError, ValueError, AttributeError):
        return False


def rerun_module() -> ModuleType:
    """``rerun``, imported with its analytics off; :class:`ViewUnavailableError` without it."""
    if not available():
        raise ViewUnavailableError(INSTALL_HINT)
    analytics_off()
    import rerun

    return rerun
