"""Learning curves from runs' ``progress.csv`` files and scatters of hyperparameter sweeps (matplotlib, off-screen)."""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hrlp.atomic import atomic_path

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: Learning curves with more lines than this get one legend below the axes instead of one inside each.
LEGEND_INSIDE_MAX = 4


def read_progress(run_dir: Path) -> dict[str, np.ndarray]:
    """A run's ``progress.csv`` as columns of floats (NaN where empty). Raises ValueError if it is missing or empty."""
    path = Path(run_dir) / "progress.csv"
    if not path.is_file():
        raise ValueError(f"{run_dir}: no progress.csv (not a training run?)")
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path}: no iterations logged yet")

    def number(line: int, row: dict[str, str | None], key: str) -> float:
        value = row.get(key)
        if value in ("", None):
            return math.nan
        try:
            return float(value)  # type: ignore[arg-type]
        except ValueError:
            raise ValueError(f"{path}, line {line}: {key} is {str(value)[:40]!r}, not a number; the log is damaged") from None

    return {k: np.array([number(n, r, k) for n, r in enumerate(rows, start=2)]) for k in rows[0]}


def plot_learning_curves(
    runs: Mapping[str, Sequence[Path]],
    out: Path,
    metrics: Sequence[str] = ("success_rate", "return_mean"),
    title: str | None = None,
) -> Path:
    """Plot ``metrics`` against environment steps, one line per label (the mean over its runs, with min-max band).

    ``runs`` maps a label (e.g. "Manager" or "flat") to the run directories of its seeds. The figure is written
    atomically to ``out`` (.png, .pdf or .svg); returns ``out``.
    """
    _check_suffix(out)
    return _save(learning_curves_figure(runs, metrics, title), out)


def learning_curves_figure(
    runs: Mapping[str, Sequence[Path]],
    metrics: Sequence[str] = ("success_rate", "return_mean"),
    title: str | None = None,
) -> Figure:
    """The figure of :func:`plot_learning_curves`, not yet written (close it with ``matplotlib.pyplot.close``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import EngFormatter

    data = {label: [read_progress(r) for r in dirs] for label, dirs in runs.items()}
    # Past a few lines a legend inside the axes hides the curves: one legend for the figure goes below them instead.
    below = len(data) > LEGEND_INSIDE_MAX
    ncol = 2 if len(data) > 8 else 1
    legend_h = 0.2 * math.ceil(len(data) / ncol) + 0.2 if below else 0.0
    fig, axes = plt.subplots(1, len(metrics), figsize=(5 * len(metrics), 3.6 + legend_h), squeeze=False)
    colors = plt.get_cmap("tab20" if len(data) > 10 else "tab10").colors  # no two lines share a colour up to 20
    for ax, metric in zip(axes[0], metrics, strict=True):
        for i, (label, logs) in enumerate(data.items()):
            logs = [lg for lg in logs if metric in lg]
            if not logs:
                continue
            grid = np.linspace(0, min(lg["env_steps"][-1] for lg in logs), 100)
            ys = np.stack([np.interp(grid, lg["env_steps"], _fill(lg[metric])) for lg in logs])
            label = f"{label} ({len(logs)} run{'s' * (len(logs) > 1)})"
            (line,) = ax.plot(grid, ys.mean(0), color=colors[i % len(colors)], label=label)
            if len(logs) > 1:
                ax.fill_between(grid, ys.min(0), ys.max(0), color=line.get_color(), alpha=0.2)
        ax.xaxis.set_major_formatter(EngFormatter())
        _label_axes(ax, "environment steps", metric.replace("_", " "), legend=not below)
    if title:
        fig.suptitle(title)
    if below:
        handles, labels = axes[0][0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=8, frameon=False)
        fig.tight_layout(rect=(0, legend_h / fig.get_figheight(), 1, 1))
    else:
        fig.tight_layout()
    return fig


def plot_sweep(
    groups: Sequence[tuple[float, Sequence[float]]],
    out: Path,
    xlabel: str,
    ylabel: str,
    log_x: bool = False,
    title: str | None = None,
) -> Path:
    """A scatter of a hyperparameter sweep in the style of the paper's Figures 4, 8 and 10: one dot per training run.

    ``groups`` holds ``(x, ys)`` pairs: the swept value of one preset run and its seeds' final metric values. Every
    seed is a dot at ``x`` (slightly jittered sideways where seeds share a value, so none hide each other) and the
    mean over the seeds is a horizontal bar. The figure is written atomically to ``out``; returns ``out``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _check_suffix(out)
    fig, ax = plt.subplots(figsize=(5, 3.6))
    xs_all = [x for x, _ in groups]
    for i, (x, ys) in enumerate(groups):
        ys = [y for y in ys if math.isfinite(y)]
        if not ys or not math.isfinite(x) or (log_x and x <= 0):
            continue
        jitter = np.linspace(-1, 1, len(ys)) if len(ys) > 1 else np.zeros(1)
        px = x * 10 ** (0.04 * jitter) if log_x else x + jitter * _spacing(xs_all)  # 0.04 decades either side
        ax.scatter(px, ys, s=22, color="C0", alpha=0.8, label="one run (seed)" if i == 0 else None, zorder=3)
        ax.scatter([x], [float(np.mean(ys))], marker="_", s=400, linewidths=2, color="C3",
                   label="mean over seeds" if i == 0 else None, zorder=4)  # fmt: skip
    if log_x:
        ax.set_xscale("log")
    _label_axes(ax, xlabel, ylabel)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return _save(fig, out)


def _label_axes(ax: Any, xlabel: str, ylabel: str, legend: bool = True) -> None:
    """Axis labels, a light grid and a small legend: the style every hrlp plot shares."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(fontsize=8)


def _spacing(xs: Sequence[float]) -> float:
    """Sideways room for jitter on a linear axis: 15% of the smallest gap between distinct x values (0.5 for one)."""
    u = np.unique([x for x in xs if math.isfinite(x)])
    return 0.5 if u.size < 2 else float(np.diff(u).min()) * 0.15


def _check_suffix(out: Path) -> None:
    if out.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise ValueError(f"plot file must end in .png, .pdf or .svg, got {out.name!r}")


def _save(fig: Figure, out: Path) -> Path:
    """Write ``fig`` to ``out`` atomically (a temporary file in the same directory, then a rename) and close it."""
    import matplotlib.pyplot as plt

    try:
        with atomic_path(out) as tmp:
            fig.savefig(tmp, dpi=120)
    finally:
        plt.close(fig)
    return out


def _fill(y: np.ndarray) -> np.ndarray:
    """Carry the last finite value over NaNs (iterations where no episode ended); leading NaNs become 0."""
    out = y.copy()
    last = 0.0
    for i, v in enumerate(out):
        if math.isnan(v):
            out[i] = last
        else:
            last = v
    return out
