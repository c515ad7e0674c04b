"""The time-series figures' common look: size, resolution, colours, fixed margins, the
title, and long lines thinned to their envelope before drawing.

Used by :mod:`tuav_sitl.figures_series` and :mod:`tuav_sitl.figures_3d`; the figures are
bare matplotlib :class:`~matplotlib.figure.Figure` objects (no pyplot global state).
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from tuav_sitl.scenario import ScenarioParams

__all__ = [
    "AXIS_COLOURS",
    "DPI",
    "ENVELOPE_BINS",
    "FIG_SIZE_IN",
    "PATH_COLOUR",
    "REF_COLOUR",
    "TETHER_COLOUR",
    "UAV_COLOUR",
    "envelope",
    "finish",
    "new_figure",
    "thin_lines",
    "title",
]

#: Size [in] and resolution [dots per inch] of the time-series figures.
FIG_SIZE_IN = (10.0, 7.0)
DPI = 110

AXIS_COLOURS = ("C0", "C1", "C2")
PATH_COLOUR = "C0"
REF_COLOUR = "k"
TETHER_COLOUR = "#8c564b"
UAV_COLOUR = "#d62728"


#: The time-series figures' margins [in]: left (tick labels and the y label), right, top
#: (the title), bottom (the time axis's label), and between panels (an axes title or the
#: tick labels of the panel below; the y label of the right-hand column).
MARGINS_IN = {"left": 0.95, "right": 0.15, "top": 0.6, "bottom": 0.5, "between": 0.5,
               "columns": 1.0}


def new_figure(size: tuple[float, float] = FIG_SIZE_IN, rows: int = 1, cols: int = 1
                ) -> Figure:
    """A figure for a ``rows`` x ``cols`` grid of time-series panels, with fixed margins
    (:data:`MARGINS_IN`).

    Fixed, not matplotlib's constrained layout: that lays every tick label out once more
    before drawing, 40 % of a figure's drawing time, for margins that hardly change from
    one run to the next."""
    fig = Figure(figsize=size, dpi=DPI)
    w, h = size
    m = MARGINS_IN
    inner_w = w - m["left"] - m["right"]
    inner_h = h - m["top"] - m["bottom"]
    # subplots_adjust's gaps are fractions of the mean panel's height and width
    panel_h = (inner_h - (rows - 1) * m["between"]) / rows
    panel_w = (inner_w - (cols - 1) * m["columns"]) / cols
    fig.subplots_adjust(left=m["left"] / w, right=1.0 - m["right"] / w,
                        bottom=m["bottom"] / h, top=1.0 - m["top"] / h,
                        hspace=m["between"] / panel_h, wspace=m["columns"] / panel_w)
    return fig


def title(fig: Figure, sc: ScenarioParams, what: str) -> None:
    """The figure's title: the scenario's name and ``what`` the figure shows."""
    fig.suptitle(f"{sc.name}: {what}", fontsize=13, fontweight="bold")


#: A time-series line with more than twice this many samples is drawn as its envelope in
#: this many runs of samples (:func:`envelope`).
ENVELOPE_BINS = 2000


def envelope(x: np.ndarray, y: np.ndarray, bins: int = ENVELOPE_BINS
             ) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` thinned to the first and last samples and the minimum and the maximum of
    ``y`` in each of ``bins`` runs of consecutive samples, in time order (``x`` ascending).

    A figure about 1000 pixels wide shows a run of ``len(x) / bins`` samples within one
    pixel column, which a line through its extremes covers exactly; every peak and every
    NaN gap (a bin holding a NaN keeps one) stays. Shorter series are returned as they are.
    """
    n = len(x)
    if n <= 2 * bins:
        return x, y
    m = -(-n // bins)                      # samples a bin
    pad = m * (-(-n // m)) - n             # the last bin padded with its last sample
    yp = np.concatenate((y, np.full(pad, y[-1]))).reshape(-1, m)
    nan = np.isnan(yp)
    base = np.arange(yp.shape[0]) * m
    imin = base + np.argmin(np.where(nan, np.inf, yp), axis=1)
    imax = base + np.argmax(np.where(nan, -np.inf, yp), axis=1)
    gaps = nan.any(axis=1)                 # a bin holding a NaN keeps one: the gap stays
    inan = (base + np.argmax(nan, axis=1))[gaps]
    ends = np.array([0, n - 1])            # the line spans the same time
    keep = np.unique(np.minimum(np.concatenate((ends, imin, imax, inan)), n - 1))
    return x[keep], y[keep]


def thin_lines(ax: Axes) -> None:
    """Each long line of ``ax`` replaced by its :func:`envelope`."""
    for line in ax.get_lines():
        x = np.asarray(line.get_xdata(), dtype=float)
        if len(x) > 2 * ENVELOPE_BINS and np.all(np.diff(x) >= 0):
            line.set_data(*envelope(x, np.asarray(line.get_ydata(), dtype=float)))


def finish(ax: Axes, ylabel: str, legend: bool = True, xlabel: bool = False) -> None:
    """A time-series panel completed: limits on its first line's span, long lines thinned
    (:func:`thin_lines`), its labels, a grid and (``legend``) a legend."""
    lines = ax.get_lines()
    if lines:
        t = np.asarray(lines[0].get_xdata(), dtype=float)
        if len(t) > 1 and t[-1] > t[0]:
            ax.set_xlim(t[0], t[-1])
    thin_lines(ax)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.4)
    if legend:
        ax.legend(loc="best", fontsize=8, framealpha=0.8)
    if xlabel:
        ax.set_xlabel("time [s]")

