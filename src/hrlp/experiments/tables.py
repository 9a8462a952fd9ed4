"""``hrlp tables``: the paper's tables and learning curves, rebuilt from run directories alone.

For each preset with finished runs under ``ROOT/PRESET/RUN/sSEED/result.json``: a markdown table
(per run: seeds, our mean with a 95% bootstrap interval across seeds, the interquartile mean with
its own, the paper's number, steps and wall time), a PNG of the learning curves (mean over seeds with a min-max band), for a
hyperparameter sweep a scatter of one dot per run against the swept value (the paper's Figures 4,
8 and 10), and for success presets a sample-efficiency table: the environment steps until the
smoothed training success rate first reaches given thresholds, with right-censored seeds.

``hrlp tables`` never replaces a file it did not write (see :func:`build_tables`): it records every file it writes,
with its sha256, in ``OUT/.hrlp-tables.json``, and replaces a file only when that record lists it with its current
content, or when asked to (``overwrite``, ``--overwrite``).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from hrlp.atomic import atomic_path, writing
from hrlp.experiments.presets import PRESETS

DEFAULT_THRESHOLDS: tuple[float, ...] = (0.05, 0.1, 0.2)
"""Training success rates whose first crossing the sample-efficiency table reports."""
SMOOTHING_WINDOW = 3
"""Iterations in the trailing average of the training success rate, so one lucky iteration does not count."""
MANIFEST = ".hrlp-tables.json"
"""The record, in the output directory, of the files ``hrlp tables`` wrote there: ``{"format": 1, "files": {name:
sha256}}``."""


def bootstrap_interval(values: list[float], confidence: float = 0.95, seed: int = 0) -> tuple[float, float, float]:
    """Mean and a percentile-bootstrap interval of the mean across seeds (a point for fewer than 2 values)."""
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return math.nan, math.nan, math.nan
    m = float(a.mean())
    if a.size < 2 or np.all(a == a[0]):
        return m, m, m
    from scipy.stats import bootstrap

    res = bootstrap((a,), np.mean, confidence_level=confidence, n_resamples=10_000, method="percentile",
                    random_state=np.random.default_rng(seed))  # fmt: skip
    return m, float(res.confidence_interval.low), float(res.confidence_interval.high)


def iqm_interval(values: Sequence[float], confidence: float = 0.95, seed: int = 0) -> tuple[float, float, float]:
    """Interquartile mean (IQM) across seeds and a percentile-bootstrap interval of it, as rliable reports them.

    The IQM is ``scipy.stats.trim_mean(values, 0.25)``: the mean after cutting ``int(0.25 * n)`` values from each end
    of the sorted values (the middle half for n divisible by 4; for fewer than 4 seeds nothing is cut, so it is the
    mean). The interval resamples the seeds with replacement (10,000 resamples, generator seeded with ``seed``, so
    the same values always give the same interval): rliable's stratified bootstrap for a single task, here one run.

    Returns ``(iqm, low, high)``: NaNs for no values; a zero-width interval ``(v, v, v)`` for a single seed or for
    values that are all equal.
    """
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return math.nan, math.nan, math.nan
    from scipy.stats import bootstrap, trim_mean

    m = float(trim_mean(a, 0.25))
    if a.size < 2 or np.all(a == a[0]):
        return m, m, m

    def iqm(x: np.ndarray, axis: int = -1) -> np.ndarray:
        return trim_mean(x, 0.25, axis=axis)

    res = bootstrap((a,), iqm, confidence_level=confidence, n_resamples=10_000, method="percentile",
                    random_state=np.random.default_rng(seed))  # fmt: skip
    return m, float(res.confidence_interval.low), float(res.confidence_interval.high)


def iqm_cell(values: Sequence[float]) -> str:
    """The table cell of :func:`iqm_interval`: ``IQM [low, high]``, the IQM alone for one seed, '-' for none."""
    m, lo, hi = iqm_interval(values)
    if math.isnan(m):
        return "-"
    return _g(m) if len(values) == 1 else f"{_g(m)} [{_g(lo)}, {_g(hi)}]"


def metric_value(result: dict[str, Any], metric: str) -> float | None:
    """The run's value of ``metric`` ('success' rate or mean 'target_dist_sum')."""
    v = result.get(metric)
    return None if v is None else float(v["mean"])


def move_cell(results: list[dict[str, Any]]) -> str:
    """What a moving run did beyond TargetDistSum, mean over its seeds: success, share of episodes with the capsule
    lifted, min d(C, T) and TargetDistSum minus an untouched capsule's ('-' for runs evaluated before these were)."""
    moves = [(r["success"], r["move"]) for r in results if r.get("move") and r.get("success")]
    if not moves:
        return "-"

    def mean(values: list[float]) -> float:
        return sum(values) / len(values)

    success = mean([s["mean"] for s, _ in moves])
    lifted = mean([m["lift_rate"]["mean"] for _, m in moves])
    closest = mean([m["min_target_dist"]["mean"] for _, m in moves])
    relative = mean([m["relative_target_dist_sum"]["mean"] for _, m in moves])
    untouched = mean([m["untouched_target_dist_sum"]["mean"] for _, m in moves])
    return f"{_g(success)} / {_g(lifted)} / {closest:.3f} m / {relative:+.1f} (untouched {untouched:.1f})"


def usage_cell(results: list[dict[str, Any]]) -> str:
    """A Manager run's share of decisions per skill, mean over its seeds (``gripper 71%, micro 29%``); '-' for flat."""
    usages = [r["macro_usage"] for r in results if r.get("macro_usage")]
    if not usages:
        return "-"
    names = dict.fromkeys(n for u in usages for n in u)
    return ", ".join(f"{n} {100 * sum(u.get(n, 0.0) for u in usages) / len(usages):.0f}%" for n in names)


def collect(root: Path) -> dict[str, dict[str, list[tuple[Path, dict[str, Any]]]]]:
    """``{preset: {run: [(run_dir, result), ...]}}`` for every ``result.json`` under ``root``."""
    out: dict[str, dict[str, list[tuple[Path, dict[str, Any]]]]] = defaultdict(lambda: defaultdict(list))
    for path in sorted(Path(root).glob("*/*/s*/result.json")):
        r = json.loads(path.read_text())
        out[r["preset"]][r["run"]].append((path.parent, r))
    return out


# --- sweeps: one dot per run against the swept hyperparameter (Figures 4, 8 and 10) -----------------------------


@dataclass(frozen=True)
class SweepAxis:
    """How a preset's swept hyperparameter is read from a run's config (``result.json["config"]``) and plotted."""

    label: str
    """The x-axis label."""
    x: Callable[[dict[str, Any]], float]
    """The swept value, from the run's full :meth:`TrainConfig.to_json` dict."""
    log: bool = False
    """Logarithmic x axis (the paper's Figures 8 and 10)."""


#: Presets that sweep one hyperparameter, and where its value lives in the config.
SWEEPS: dict[str, SweepAxis] = {
    "reach-and-move-flat": SweepAxis("TargetCoeff", lambda c: c["task_kwargs"]["target_coeff"]),
    # Figure 8's axis is 10^5 * alpha: the angle the curriculum reaches after 10^5 episodes.
    "reach-and-grip-2-flat": SweepAxis("10⁵·α", lambda c: 1e5 * c["task_kwargs"]["curriculum_alpha"], log=True),
    "reach-and-grip-2-flat-kl": SweepAxis("max KL", lambda c: c["trpo"]["max_kl"], log=True),
    **{
        name + tuned: axis
        for name, axis in (
            ("manager-kl", SweepAxis("max KL", lambda c: c["trpo"]["max_kl"], log=True)),
            ("manager-k", SweepAxis("macro-action length k", lambda c: c["macro"]["k"])),
            ("manager-size", SweepAxis("hidden layer width", lambda c: c["hidden"][0], log=True)),
        )
        for tuned in ("", "-tuned")
    },
}


def sweep_x(preset: str, config: dict[str, Any]) -> float | None:
    """The swept hyperparameter of ``preset`` in a run's config dict; None for a preset without a sweep or a config
    that lacks the setting (e.g. a run written by an older preset)."""
    axis = SWEEPS.get(preset)
    if axis is None:
        return None
    try:
        return float(axis.x(config))
    except (KeyError, IndexError, TypeError):
        return None


# --- grids: presets whose runs are ROW,COLUMN cells of one of the paper's figures (Figure 7) ------------------------

#: Presets laid out as the paper's Figures 6 and 7: run ``SKILLS,c2=X,tr=Y`` is row SKILLS, column ``c2=X,tr=Y``.
GRIDS = frozenset(
    {
        "reach-and-grip-1",
        "reach-and-grip-1-tuned",
        "reach-and-grip-1-handover",
        "reach-and-grip-2",
        "reach-and-grip-2-tuned",
        "reach-and-grip-2-handover",
    }
)


def grid_lines(cells: dict[str, tuple[str, float | None]]) -> list[str]:
    """A markdown table with one row per skill set and one column per reward cell, each ``ours (paper)``.

    Args:
        cells: run name ``ROW,COLUMN`` (split at the first comma) -> (our formatted figure, the paper's or None).
    """
    rows: dict[str, dict[str, str]] = {}
    columns: list[str] = []
    for name, (ours, paper) in cells.items():
        row, sep, col = name.partition(",")
        if not sep:
            raise ValueError(f"grid run {name!r} is not ROW,COLUMN")
        if col not in columns:
            columns.append(col)
        rows.setdefault(row, {})[col] = ours + ("" if paper is None else f" ({paper:g})")
    lines = ["| | " + " | ".join(c.replace(",", ", ") for c in columns) + " |", "|---|" + "---|" * len(columns)]
    lines += [f"| {row} | " + " | ".join(r.get(c, "") for c in columns) + " |" for row, r in rows.items()]
    return lines


# --- sample efficiency: steps until the training success rate first reaches a threshold ------------------------


def smoothed_rate(rate: np.ndarray, episodes: np.ndarray | None = None, window: int = SMOOTHING_WINDOW) -> np.ndarray:
    """The trailing average of a per-iteration rate over the last ``window`` iterations, shape ``[iterations]``.

    With ``episodes`` (episodes finished per iteration) the average is weighted by them, i.e. it is the success rate
    of all training episodes that ended in those iterations. Iterations without a finite rate (no episode ended) are
    left out of their windows. The first ``window - 1`` entries are NaN: only full windows count.
    """
    if window < 1:
        raise ValueError(f"window must be a positive number of iterations, got {window}")
    rate = np.asarray(rate, dtype=float)
    w = np.ones_like(rate) if episodes is None else np.asarray(episodes, dtype=float)
    out = np.full(rate.shape, math.nan)
    for i in range(window - 1, rate.size):
        r, wi = rate[i - window + 1 : i + 1], w[i - window + 1 : i + 1]
        ok = np.isfinite(r) & np.isfinite(wi) & (wi > 0)
        if ok.any():
            out[i] = float((r[ok] * wi[ok]).sum() / wi[ok].sum())
    return out


def steps_to_threshold(
    env_steps: np.ndarray,
    rate: np.ndarray,
    threshold: float,
    episodes: np.ndarray | None = None,
    window: int = SMOOTHING_WINDOW,
) -> float | None:
    """``env_steps`` at the end of the first iteration whose :func:`smoothed_rate` is at least ``threshold``.

    None if it never gets there: the run is right-censored at its last ``env_steps``.
    """
    hit = np.flatnonzero(smoothed_rate(rate, episodes, window) >= threshold)
    return float(env_steps[hit[0]]) if hit.size else None


def censored_median(values: Sequence[float], reached: Sequence[bool]) -> tuple[float, bool]:
    """The median over seeds of a time-to-event where some seeds are right-censored, and whether it is exact.

    ``values[i]`` is seed i's crossing step if ``reached[i]``, else its final step count (its true crossing step is
    larger, if it ever comes). Returns the median of these values, a lower bound of the true median; it is exact when
    the ``n // 2 + 1`` smallest true values are known, i.e. at least that many reached values lie at or below every
    censoring point (each censored seed then lies above them, whatever its true value).
    """
    if len(values) != len(reached) or not values:
        raise ValueError("need one reached flag per value, and at least one value")
    v = np.asarray(values, dtype=float)
    r = np.asarray(reached, dtype=bool)
    first_censored = v[~r].min() if (~r).any() else math.inf
    exact = int((v[r] <= first_censored).sum()) >= v.size // 2 + 1
    return float(np.median(v)), exact


class Crossing(NamedTuple):
    """Steps to one threshold over a run's seeds; censored seeds count their final step count in ``steps``."""

    steps: tuple[float, ...]
    """Per seed: the crossing step, or the final step count where it never crossed."""
    reached: tuple[bool, ...]
    """Per seed: whether it crossed."""

    @property
    def n_reached(self) -> int:
        """Seeds that reached the threshold."""
        return sum(self.reached)

    def median(self) -> tuple[float, bool]:
        """:func:`censored_median`: the median over seeds (a lower bound unless the flag says exact)."""
        return censored_median(self.steps, self.reached)

    def cell(self) -> str:
        """The table cell: mean [95% bootstrap interval] if every seed reached it, else the censored median."""
        n = len(self.steps)
        count = f"({self.n_reached}/{n})"
        if self.n_reached == n:
            m, lo, hi = bootstrap_interval(list(self.steps))
            interval = "" if n == 1 else f" [{format_steps(lo)}, {format_steps(hi)}]"
            return f"{format_steps(m)}{interval} {count}"
        if self.n_reached:  # say where the others were censored: each never got there within its own steps
            first_censored = min(s for s, r in zip(self.steps, self.reached, strict=True) if not r)
            count = f"({self.n_reached}/{n}, rest > {format_steps(first_censored)})"
        med, exact = self.median()
        return f"median {format_steps(med)} {count}" if exact else f"≥ {format_steps(med)} {count}"


def run_crossings(
    logs: Sequence[dict[str, np.ndarray]], thresholds: Sequence[float], window: int = SMOOTHING_WINDOW
) -> list[Crossing]:
    """One :class:`Crossing` per threshold for the seeds' progress logs (:func:`hrlp.plots.read_progress`).

    The rate is the column ``success_rate`` (training episodes), weighted by ``episodes`` where logged; a log without
    ``success_rate`` never crosses.
    """
    out = []
    for th in thresholds:
        steps, reached = [], []
        for lg in logs:
            t = None
            if "success_rate" in lg:
                t = steps_to_threshold(lg["env_steps"], lg["success_rate"], th, lg.get("episodes"), window)
            steps.append(float(lg["env_steps"][-1]) if t is None else t)
            reached.append(t is not None)
        out.append(Crossing(tuple(steps), tuple(reached)))
    return out


def speedup(manager: Crossing, flat: Crossing) -> tuple[float, str] | None:
    """How many times fewer steps the Manager needs than the flat run (ratio of censored medians, flat / Manager).

    Returns the ratio and its relation to the true ratio of medians: "=" if both medians are exact, ">=" if only the
    Manager's is (the flat one is a lower bound), "<=" if only the flat one's is; None if neither is exact.
    """
    (m_man, man_exact), (m_flat, flat_exact) = manager.median(), flat.median()
    if not (man_exact or flat_exact):
        return None
    rel = "=" if man_exact and flat_exact else ">=" if man_exact else "<="
    return m_flat / m_man, rel


def format_steps(v: float) -> str:
    """Environment steps, short: 950, 12.5k, 3M."""
    if not math.isfinite(v):
        return "-"
    if abs(v) >= 1e6:
        return f"{v / 1e6:.3g}M"
    if abs(v) >= 1e3:
        return f"{v / 1e3:.3g}k"
    return f"{v:.0f}"


def sample_efficiency_lines(
    runs: dict[str, tuple[bool, list[dict[str, np.ndarray]]]],
    thresholds: Sequence[float] = DEFAULT_THRESHOLDS,
    window: int = SMOOTHING_WINDOW,
) -> list[str]:
    """The markdown section of the sample-efficiency table: a row per run (``{name: (is_manager, seed logs)}``, in
    table order) and, where the preset has both Managers and flat runs, a line per threshold comparing the best of
    each by :func:`speedup`."""
    pct = [f"{th:.0%}" if th * 100 == round(th * 100) else f"{th:g}" for th in thresholds]
    lines = [
        "## Sample efficiency",
        "",
        f"Environment steps until the training success rate, averaged over the last {window} iterations (weighted by "
        "episodes), first reaches each threshold. A cell is the mean over seeds with a 95% bootstrap interval when "
        "every seed got there; otherwise a seed that never got there counts as right-censored at its final step count "
        "and the cell is the median over seeds: `median X` when the censored seeds cannot change it, `≥ X` (a lower "
        "bound) when they can. (r/n): seeds that reached the threshold; `rest > Y`: the others never did within Y steps.",
        "",
        "| run | kind | seeds | " + " | ".join(f"steps to {p}" for p in pct) + " |",
        "|---|---|---:|" + "---|" * len(thresholds),
    ]
    crossings = {name: run_crossings(logs, thresholds, window) for name, (_, logs) in runs.items()}
    for name, (is_manager, logs) in runs.items():
        cells = " | ".join(c.cell() for c in crossings[name])
        lines.append(f"| {name} | {'Manager' if is_manager else 'flat'} | {len(logs)} | {cells} |")
    managers = [n for n, (m, _) in runs.items() if m]
    flats = [n for n, (m, _) in runs.items() if not m]
    if managers and flats:
        lines += [
            "",
            "Best Manager against best flat run, by median steps over seeds. The Manager is the one with the smallest "
            "known median (lower bounds only where no Manager run has one), the flat run the one with the smallest median "
            "or lower bound, so censoring never inflates the ratio:",
            "",
        ]
        for i, p in enumerate(pct):
            man = min(managers, key=lambda n: (not crossings[n][i].median()[1], crossings[n][i].median()[0]))
            flat = min(flats, key=lambda n: crossings[n][i].median()[0])
            cm, cf = crossings[man][i], crossings[flat][i]
            desc = f"`{man}` {_median_cell(cm)} vs `{flat}` {_median_cell(cf)}"
            s = speedup(cm, cf)
            if s is None:
                verdict = "undetermined (neither median is reached by enough seeds)"
            else:
                ratio, rel = s
                word = {"=": "", ">=": "at least ", "<=": "at most "}[rel]
                verdict = f"the Manager needs {word}{ratio:.3g}x fewer environment steps"
            lines.append(f"- success {p}: {desc}: {verdict}.")
    return lines


def _median_cell(c: Crossing) -> str:
    med, exact = c.median()
    return f"{'' if exact else '≥ '}{format_steps(med)} ({c.n_reached}/{len(c.steps)})"


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_manifest(out: Path) -> dict[str, str]:
    """``{file name: sha256}`` of the files ``hrlp tables`` wrote to ``out`` (:data:`MANIFEST`); {} if none (or a
    manifest that cannot be read, which then vouches for nothing)."""
    try:
        doc = json.loads((Path(out) / MANIFEST).read_text())
    except (OSError, ValueError):
        return {}
    files = doc.get("files") if isinstance(doc, dict) else None
    if not isinstance(files, dict):
        return {}
    return {k: v for k, v in files.items() if isinstance(k, str) and isinstance(v, str)}


def foreign_files(out: Path, names: Sequence[str]) -> list[str]:
    """Those of ``names`` that exist in ``out`` but were not written there by ``hrlp tables`` as they are now: not in
    its manifest, or changed since (their sha256 differs from the recorded one)."""
    recorded = read_manifest(out)
    return [n for n in names if (Path(out) / n).exists() and recorded.get(n) != _sha256(Path(out) / n)]


def _record(out: Path, written: Path) -> None:
    """Add ``written`` (a file in ``out``) with its current sha256 to the manifest, atomically."""
    files = read_manifest(out)
    files[written.name] = _sha256(written)
    with atomic_path(out / MANIFEST) as tmp:
        tmp.write_text(json.dumps({"format": 1, "files": dict(sorted(files.items()))}, indent=2) + "\n")


def default_out(root: Path) -> Path:
    """Where ``hrlp tables --root ROOT`` writes without ``--out``: ``ROOT/tables``, beside the runs it is built from
    (never a directory of committed results, such as ``docs/results``)."""
    return Path(root) / "tables"


def build_tables(
    root: Path,
    out: Path,
    thresholds: Sequence[float] | None = None,
    window: int = SMOOTHING_WINDOW,
    overwrite: bool = False,
) -> list[Path]:
    """Write ``out/PRESET.md`` and ``out/PRESET.png`` for every preset with results, and ``out/PRESET_scatter.png`` for
    presets that sweep a hyperparameter (:data:`SWEEPS`); returns the files written.

    A file of those names that already exists is replaced only if this function wrote it (it is listed in
    ``out/.hrlp-tables.json`` with the sha256 it has now: not edited since) or ``overwrite`` is true; otherwise
    ValueError names the files, before anything is written. Each file written is recorded in that manifest.

    Each run's cell is the mean over seeds with a 95% percentile-bootstrap interval across seeds; a run with a
    single seed shows that run's own interval over its evaluation episodes (Wilson for success). Beside it, the
    interquartile mean over seeds with its own bootstrap interval (:func:`iqm_interval`). Presets whose
    metric is success also get a sample-efficiency table (:func:`sample_efficiency_lines`) at ``thresholds`` of the
    training success rate, smoothed over ``window`` iterations (None: each preset's own :attr:`Preset.thresholds`,
    else :data:`DEFAULT_THRESHOLDS`).
    """
    from hrlp.plots import plot_learning_curves, read_progress

    if thresholds is not None and (not thresholds or not all(0 < th <= 1 for th in thresholds)):
        raise ValueError(f"success thresholds must lie in (0, 1], got {list(thresholds)}")
    if window < 1:
        raise ValueError(f"the smoothing window must be at least 1 iteration, got {window}")
    data = collect(root)
    if not data:
        raise ValueError(f"no finished runs (result.json) under {root}; run 'hrlp reproduce PRESET' first")
    out = Path(out)
    planned = []
    for preset_name, runs in data.items():
        preset = PRESETS.get(preset_name)
        order = [r.name for r in preset.runs if r.name in runs] if preset else sorted(runs)
        metric = preset.metric if preset else "success"
        planned += [f"{preset_name}.md", f"{preset_name}.png"]
        axis = SWEEPS.get(preset_name)
        if axis is not None and _sweep_groups(preset_name, metric, [runs[n] for n in order]):
            planned.append(f"{preset_name}_scatter.png")
    if not overwrite and (foreign := foreign_files(out, planned)):
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise ValueError(f"{out}: would replace {shown}, which hrlp tables did not write there (or which changed since); "
                         "pass --overwrite to replace them, or choose another --out")  # fmt: skip
    with writing(out):
        out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []

    def wrote(path: Path) -> None:
        _record(out, path)
        written.append(path)

    for preset_name, runs in data.items():
        preset = PRESETS.get(preset_name)
        metric = preset.metric if preset else "success"
        order = [r.name for r in preset.runs if r.name in runs] if preset else sorted(runs)
        axis = SWEEPS.get(preset_name)
        lines = [
            f"# {preset_name}" + (f": {preset.description} ({preset.source})" if preset else ""),
            "",
            f"Metric: {metric.replace('_', ' ')} (mean over seeds, 95% bootstrap interval across seeds; for a single "
            "seed, that run's own 95% interval over its evaluation episodes). IQM: the interquartile mean over seeds "
            "(`scipy.stats.trim_mean(x, 0.25)`, the mean for fewer than 4 seeds) with a 95% percentile-bootstrap "
            "interval over seeds. "
            f"Rebuild: `hrlp tables --root {root} --out {out}`.",
            "",
            f"Figures: `{preset_name}.png` (learning curves)"
            + (f", `{preset_name}_scatter.png` (the metric against {axis.label}, one dot per seed)" if axis else "")
            + ".",
            "",
        ]
        managers = any(r.get("macro_usage") for name in order for _, r in runs[name])
        copied = sorted({r["copied_from"].split("/")[0] for name in order for _, r in runs[name] if r.get("copied_from")})
        if copied:
            lines += [
                f"Runs marked * were copied from {', '.join(f'`{c}`' for c in copied)} (same config and seed); their "
                "wall time is that of the original runs.",
                "",
            ]
        # Moving presets, and any other whose runs recorded what the capsule did (a success-metric reach-and-move preset).
        moving = metric == "target_dist_sum" or any(r.get("move") for name in order for _, r in runs[name])
        lines += [
            "| run | seeds | ours | IQM | paper | env steps per run | wall time (h, all seeds) |"
            + (" success / lifted / min d(C, T) / TargetDistSum minus untouched |" if moving else "")
            + (" decisions per skill (mean over seeds) |" if managers else ""),
            "|---|---:|---|---|---:|---:|---:|" + ("---|" if moving else "") + ("---|" if managers else ""),
        ]
        grid: dict[str, tuple[str, float | None]] = {}
        for name in order:
            results = [r for _, r in runs[name]]
            values = [v for v in (metric_value(r, metric) for r in results) if v is not None]
            m, lo, hi = bootstrap_interval(values)
            if len(results) == 1 and results[0].get(metric):  # one seed: its own interval over evaluation episodes
                lo, hi = float(results[0][metric]["low"]), float(results[0][metric]["high"])
            paper = results[0].get("paper")
            steps = sorted({int(r["env_steps"]) for r in results})
            wall = sum(float(r["wall_s"]) for r in results) / 3600
            paper_cell = "-" if paper is None else f"{paper:g}"
            steps_cell = ", ".join(f"{s:,}" for s in steps)
            ours = f"{_g(m)} [{_g(lo)}, {_g(hi)}]"
            star = "*" if any(r.get("copied_from") for r in results) else ""
            row = f"| {name}{star} | {len(results)} | {ours} | {iqm_cell(values)} | {paper_cell} | {steps_cell} | {wall:.2f} |"
            lines.append(
                row + (f" {move_cell(results)} |" if moving else "") + (f" {usage_cell(results)} |" if managers else "")
            )
            grid[name] = (_g(m), paper)
        if preset_name in GRIDS:
            lines += ["", f"The same as the paper's figure lays it out: {metric.replace('_', ' ')}, ours (paper's).", ""]
            lines += grid_lines(grid)
        if metric == "success":
            logs = {
                name: (runs[name][0][1]["config"].get("macro") is not None, [read_progress(d) for d, _ in runs[name]])
                for name in order
            }
            own = thresholds or (preset.thresholds if preset and preset.thresholds else DEFAULT_THRESHOLDS)
            lines += ["", *sample_efficiency_lines(logs, own, window)]
        md = out / f"{preset_name}.md"
        with atomic_path(md) as tmp:
            tmp.write_text("\n".join(lines) + "\n")
        wrote(md)
        curves = {name: [d for d, _ in runs[name]] for name in order}
        metrics = ("success_rate", "return_mean") if metric == "success" else ("target_dist_sum", "return_mean")
        wrote(plot_learning_curves(curves, out / f"{preset_name}.png", metrics=metrics, title=preset_name))
        if axis is not None and (scatter := _sweep_scatter(preset_name, axis, metric, [runs[n] for n in order], out)):
            wrote(scatter)
    return written


def _sweep_scatter(
    preset_name: str, axis: SweepAxis, metric: str, runs: list[list[tuple[Path, dict[str, Any]]]], out: Path
) -> Path | None:
    """``out/PRESET_scatter.png``: every seed's final ``metric`` at its run's swept value; None if no run has both."""
    from hrlp.plots import plot_sweep

    groups = _sweep_groups(preset_name, metric, runs)
    if not groups:
        return None
    ylabel = {"success": "success rate (Definition 1)", "target_dist_sum": "TargetDistSum"}.get(metric, metric)
    return plot_sweep(groups, out / f"{preset_name}_scatter.png", axis.label, ylabel, axis.log, preset_name)


def _sweep_groups(
    preset_name: str, metric: str, runs: list[list[tuple[Path, dict[str, Any]]]]
) -> list[tuple[float, list[float]]]:
    """The scatter's ``(swept value, seeds' metric values)`` per run that has both."""
    groups = []
    for seeds in runs:
        xs = {sweep_x(preset_name, r["config"]) for _, r in seeds}
        ys = [v for v in (metric_value(r, metric) for _, r in seeds) if v is not None]
        x = xs.pop() if len(xs) == 1 else None
        if x is not None and ys:
            groups.append((x, ys))
    return groups


def _g(x: float) -> str:
    """Three significant digits; rounding noise next to 0 (an old Wilson bound of 3.5e-18) shows as 0."""
    return "0" if abs(x) < 1e-12 else f"{x:.3g}"
