"""``hrlp tables``: the paper's tables and learning curves, rebuilt from run directories alone.

For each preset with finished runs under ``ROOT/PRESET/RUN/sSEED/result.json``: a markdown table
(per run: seeds, our mean with a 95% bootstrap interval across seeds, the paper's number, steps
and wall time) and a PNG of the learning curves (mean over seeds with a min-max band).
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from hrlp.experiments.presets import PRESETS


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


def metric_value(result: dict[str, Any], metric: str) -> float | None:
    """The run's value of ``metric`` ('success' rate or mean 'target_dist_sum')."""
    v = result.get(metric)
    return None if v is None else float(v["mean"])


def collect(root: Path) -> dict[str, dict[str, list[tuple[Path, dict[str, Any]]]]]:
    """``{preset: {run: [(run_dir, result), ...]}}`` for every ``result.json`` under ``root``."""
    out: dict[str, dict[str, list[tuple[Path, dict[str, Any]]]]] = defaultdict(lambda: defaultdict(list))
    for path in sorted(Path(root).glob("*/*/s*/result.json")):
        r = json.loads(path.read_text())
        out[r["preset"]][r["run"]].append((path.parent, r))
    return out


def build_tables(root: Path, out: Path) -> list[Path]:
    """Write ``out/PRESET.md`` and ``out/PRESET.png`` for every preset with results; returns the files written.

    Each run's cell is the mean over seeds with a 95% percentile-bootstrap interval across seeds; a run with a
    single seed shows that run's own interval over its evaluation episodes (Wilson for success).
    """
    from hrlp.plots import plot_learning_curves

    data = collect(root)
    if not data:
        raise ValueError(f"no finished runs (result.json) under {root}; run 'hrlp reproduce PRESET' first")
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for preset_name, runs in data.items():
        preset = PRESETS.get(preset_name)
        metric = preset.metric if preset else "success"
        order = [r.name for r in preset.runs if r.name in runs] if preset else sorted(runs)
        lines = [
            f"# {preset_name}" + (f": {preset.description} ({preset.source})" if preset else ""),
            "",
            f"Metric: {metric.replace('_', ' ')} (mean over seeds, 95% bootstrap interval across seeds; for a single "
            "seed, that run's own 95% interval over its evaluation episodes). "
            f"Rebuild: `hrlp tables --root {root} --out {out}`.",
            "",
            "| run | seeds | ours | paper | env steps per run | wall time (h, all seeds) |",
            "|---|---:|---|---:|---:|---:|",
        ]
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
            ours = f"{m:.3g} [{lo:.3g}, {hi:.3g}]"
            lines.append(f"| {name} | {len(results)} | {ours} | {paper_cell} | {steps_cell} | {wall:.2f} |")
        md = out / f"{preset_name}.md"
        md.write_text("\n".join(lines) + "\n")
        written.append(md)
        curves = {name: [d for d, _ in runs[name]] for name in order}
        metrics = ("success_rate", "return_mean") if metric == "success" else ("target_dist_sum", "return_mean")
        written.append(plot_learning_curves(curves, out / f"{preset_name}.png", metrics=metrics, title=preset_name))
    return written
