"""The one look of hyst's figures: panel size, resolution, fonts, line widths, the colour of each
role a line plays, grid and legends, and :func:`new_figure`, which every figure function starts
from.

A figure function draws each line with the role it plays (``ax.plot(x, y, **line("measured"))``)
rather than a colour of its own, so the measured data, the model, the reference and so on look the
same in every figure hyst draws. Figures are ``matplotlib.figure.Figure`` objects on an Agg canvas:
no pyplot, no global state, no display. matplotlib is imported inside :func:`new_figure` only, so
importing this module costs nothing.
"""
from __future__ import annotations

from typing import Any

DPI = 100
"""Dots per inch of every figure, on screen and in its PNG."""

PANEL_SIZE = (4.2, 3.5)
"""Width and height of one panel (inches): a figure of ``rows`` x ``cols`` panels is
``cols * 4.2`` by ``rows * 3.5`` inches (the paper's Figs. 6 and 7 at 100 dpi)."""

TITLE_SIZE = 9
SUPTITLE_SIZE = 9
LABEL_SIZE = 9
TICK_SIZE = 8
LEGEND_SIZE = 7
NOTE_SIZE = 7
"""Font sizes (points): panel titles, the figure's title, axis labels, tick labels, legends, and
notes written on a panel (bar values, 'no motor current recorded')."""

LINE_WIDTH = 1.4
THIN_WIDTH = 1.0
MARKER_SIZE = 3
EDGE_MARKER_SIZE = 7
"""Line widths (points) of a drawn series and of marks and guides (edges, search steps); the
size of a series' markers and of the one point a figure is about (the edge a search found)."""

GRID = {"linewidth": 0.3, "alpha": 0.6}
"""Every panel's grid."""

BAND_ALPHA = 0.15
INTERVAL_ALPHA = 0.35
"""Opacity of a shaded span (a dead zone), and of an interval's, often a degree or less wide and
so darker to be seen: the lines under either stay readable."""

LEGEND_LOC = "best"
FIGURE_LEGEND_LOC = "lower center"
"""Where a panel's legend goes, and a legend shared by a whole figure."""

COLOURS: dict[str, str] = {
    "measured": "0.4",         # what a sensor recorded: the tip angle, the motor current
    "background": "0.8",       # a whole record drawn behind the part a figure is about
    "model": "tab:blue",       # what a model predicts
    "augmented": "tab:brown",  # the model with the effects a diagnosis added
    "reference": "black",      # what was asked for: the reference r, the ideal y = r
    "compensated": "tab:red",  # a compensated run, the paper's red
    "shifted": "tab:green",    # the shifted dead zone and the edge the search found, the paper's green
    "interval": "tab:orange",  # an uncertainty interval, drawn as a band
    "warning": "tab:purple",   # where a search was refused or stopped: contacts
    "edge": "0.3",             # dead-zone edges of a model
    "loading": "tab:red",      # the ascending envelope f_up
    "unloading": "tab:blue",   # the descending envelope f_dn
    "region": "0.9",           # the states between the two envelopes
}
"""The colour of each role a line, band or mark plays."""

LINESTYLES: dict[str, str] = {"reference": "--", "edge": "--", "warning": ":"}
"""Roles drawn in a line style other than solid."""

THIN_ROLES = frozenset({"background", "edge", "reference", "warning"})
"""Roles drawn at :data:`THIN_WIDTH`: guides and context, thinner than the series they frame."""

SERIES = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive",
          "tab:cyan")
"""Colours of series that are categories rather than roles (groups of a batch, kinds of bar), in
turn."""

CONTROLLER_COLOURS: dict[str, str] = {"none": "tab:blue", "comp": COLOURS["compensated"],
                                      "comp+shift": COLOURS["shifted"]}
"""The paper's colours of the evaluation's controllers (Figs. 6 and 7); any other controller takes
the next of :data:`SERIES` they leave."""


def line(role: str, **overrides: Any) -> dict[str, Any]:
    """Keyword arguments of ``Axes.plot`` (or ``axvline``) for a line playing ``role``."""
    kw: dict[str, Any] = {"color": COLOURS[role], "linewidth": THIN_WIDTH if role in THIN_ROLES else LINE_WIDTH,
                          "linestyle": LINESTYLES.get(role, "-")}
    kw.update(overrides)
    return kw


def band(role: str, **overrides: Any) -> dict[str, Any]:
    """Keyword arguments of ``Axes.axvspan`` (or ``fill_between``) for a shaded span playing ``role``."""
    alpha = {"region": 1.0, "interval": INTERVAL_ALPHA}.get(role, BAND_ALPHA)
    kw: dict[str, Any] = {"color": COLOURS[role], "alpha": alpha, "linewidth": 0}
    kw.update(overrides)
    return kw


def series_colour(i: int) -> str:
    """The ``i``-th category's colour (:data:`SERIES`, round again after the last)."""
    return SERIES[i % len(SERIES)]


def controller_colour(name: str, extra: dict[str, str]) -> str:
    """The colour of controller ``name``: the paper's, else the next unused one of :data:`SERIES`,
    remembered in ``extra`` so one figure gives a controller one colour."""
    if name in CONTROLLER_COLOURS:
        return CONTROLLER_COLOURS[name]
    if name not in extra:
        free = [c for c in SERIES if c not in CONTROLLER_COLOURS.values()]
        extra[name] = free[len(extra) % len(free)]
    return extra[name]


def new_figure(rows: int = 1, cols: int = 1, sharex: bool = False) -> tuple[Any, Any]:
    """A Figure of ``rows`` x ``cols`` panels in the style, and its axes.

    Returns
    -------
    matplotlib.figure.Figure
        :data:`PANEL_SIZE` per panel at :data:`DPI`, on an Agg canvas (drawn and measured without
        pyplot or a display).
    numpy.ndarray of matplotlib.axes.Axes
        Shape ``(rows, cols)``, each with the grid and the tick and label sizes of the style.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(PANEL_SIZE[0] * cols, PANEL_SIZE[1] * rows), dpi=DPI)
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, sharex=sharex, squeeze=False)
    for ax in axes.flat:
        ax.grid(True, **GRID)
        ax.tick_params(labelsize=TICK_SIZE)
        ax.xaxis.label.set_fontsize(LABEL_SIZE)
        ax.yaxis.label.set_fontsize(LABEL_SIZE)
    return fig, axes


def title(ax: Any, text: str) -> None:
    """Set a panel's title in the style."""
    ax.set_title(text, fontsize=TITLE_SIZE)


def legend(target: Any, *args: Any, **overrides: Any) -> Any:
    """A legend in the style on ``target``: an Axes (at :data:`LEGEND_LOC`) or a Figure (one legend
    for all its panels, at :data:`FIGURE_LEGEND_LOC`, no frame)."""
    from matplotlib.figure import Figure

    kw: dict[str, Any] = {"fontsize": LEGEND_SIZE}
    if isinstance(target, Figure):
        kw.update(loc=FIGURE_LEGEND_LOC, frameon=False)
    else:
        kw.update(loc=LEGEND_LOC)
    kw.update(overrides)
    return target.legend(*args, **kw)


def finish(fig: Any) -> None:
    """Lay the panels out tight around their labels, titles and the figure's title."""
    fig.tight_layout()


__all__ = ["BAND_ALPHA", "COLOURS", "CONTROLLER_COLOURS", "DPI", "EDGE_MARKER_SIZE", "FIGURE_LEGEND_LOC", "GRID",
           "INTERVAL_ALPHA", "LABEL_SIZE", "LEGEND_LOC", "LEGEND_SIZE", "LINESTYLES", "LINE_WIDTH", "MARKER_SIZE",
           "NOTE_SIZE", "PANEL_SIZE", "SERIES", "SUPTITLE_SIZE", "THIN_ROLES", "THIN_WIDTH", "TICK_SIZE", "TITLE_SIZE",
           "band", "controller_colour", "finish", "legend", "line", "new_figure", "series_colour", "title"]
