"""Logging a run: ``progress.csv`` and TensorBoard (:class:`RunLogger`), and the one-line progress reports."""

from __future__ import annotations

import csv
import math
from pathlib import Path

from hrlp.atomic import atomic_path, writing
from hrlp.config import ALGOS


class RunLogger:
    """Writes each iteration's statistics to ``progress.csv`` and TensorBoard under the run directory."""

    def __init__(self, run_dir: Path) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.run_dir = run_dir
        self._csv_path = run_dir / "progress.csv"
        self._fields: list[str] | None = None
        with writing(run_dir / "tb"):
            self._tb = SummaryWriter(str(run_dir / "tb"))

    def log(self, stats: dict[str, float]) -> None:
        """Append one row. The header comes from the first row, or from the file a resumed run already wrote; a
        statistic that file lacks (logged by a later version of hrlp) widens its header, older rows leaving it empty."""
        if self._fields is None:
            rows = _read_csv(self._csv_path)
            if rows:
                added = [k for k in stats if k not in rows[0]]
                if added:
                    _write_csv(self._csv_path, [rows[0] + added] + [r + [""] * len(added) for r in rows[1:]])
                self._fields = rows[0] + added
            else:
                self._fields = list(stats)
                _write_csv(self._csv_path, [self._fields])
        with writing(self._csv_path), self._csv_path.open("a", newline="") as f:
            csv.writer(f).writerow([stats.get(k, math.nan) for k in self._fields])
            f.flush()  # a full disk shows here, inside writing(), not at an implicit close
        step = int(stats["env_steps"])
        with writing(self.run_dir / "tb"):
            for k, v in stats.items():
                if isinstance(v, int | float) and math.isfinite(v):
                    self._tb.add_scalar(k, v, step)
            self._tb.flush()

    def close(self) -> None:
        """Flush and close TensorBoard."""
        self._tb.close()


def update_stat(stats: dict[str, float], name: str, default: float = math.nan) -> float:
    """The policy update's statistic ``name`` (``kl``, ``accepted``, ...) in an iteration's ``stats``, whichever optimiser
    logged it (``trpo/kl`` or ``ppo/kl``)."""
    for algo in ALGOS:
        if f"{algo}/{name}" in stats:
            return stats[f"{algo}/{name}"]
    return default


def progress_line(label: str, stats: dict[str, float], total: int, elapsed_s: float, episodes: int | None = None) -> str:
    """One line for an iteration's statistics: what a log written to a file shows instead of a progress bar, e.g.
    ``train Reacher: iteration 3, 150,000/1,000,000 steps (15%), return -40.2, success 0.12, kl 0.0098, 2714 steps/s,
    55 s``; with an episode budget ``episodes``, the episodes finished of it after the steps. An iteration in which no
    episode ended shows ``return -`` (never ``nan``)."""
    done = int(stats["env_steps"])
    total = max(total, done, 1)
    out = f"{label}: iteration {int(stats['iteration'])}, {done:,}/{total:,} steps ({done / total:.0%})"
    if episodes is not None and "episodes_total" in stats:
        out += f", {int(stats['episodes_total']):,}/{episodes:,} episodes"
    out += f", return {shown(stats['return_mean'], '.1f')}"
    if not math.isnan(stats["success_rate"]):
        out += f", success {stats['success_rate']:.2f}"
    if not math.isnan(kl := update_stat(stats, "kl")):  # an off-policy update has no KL step
        out += f", kl {kl:.4f}"
    return out + f", {stats['time/steps_per_s']:.0f} steps/s, {elapsed_s:.0f} s"


def shown(value: float, spec: str) -> str:
    """``value`` formatted with ``spec`` for a progress report, or ``-`` where it is NaN (no episode ended in the
    iteration, so there is no return to show) or missing."""
    return "-" if value is None or math.isnan(value) else format(value, spec)


def truncate_log(path: Path, iteration: int) -> None:
    """Keep the header and the rows up to ``iteration`` (a kill between a row and its checkpoint leaves one row more).

    A row whose first column is not an iteration number (a damaged file) is a ValueError naming the file and the line,
    before anything is rewritten."""
    rows = _read_csv(path)
    if rows:
        kept = [r for n, r in enumerate(rows[1:], start=2) if r and row_iteration(path, n, r) <= iteration]
        _write_csv(path, [rows[0], *kept])


def row_iteration(path: Path, line: int, row: list[str]) -> int:
    """The iteration number in the first column of ``row``, line ``line`` of the log ``path``; a ValueError naming
    both where it is not one."""
    try:
        value = float(row[0])
        if value.is_integer():
            return int(value)
    except ValueError:
        pass
    raise ValueError(f"{path}, line {line}: {row[0][:40]!r} where an iteration number belongs; the log is damaged: "
                     "repair or remove that line")  # fmt: skip


def _read_csv(path: Path) -> list[list[str]]:
    """Every row of a CSV file, the header first; [] if there is no file."""
    if not path.exists():
        return []
    with path.open(newline="") as f:
        return list(csv.reader(f))


def _write_csv(path: Path, rows: list[list[str]]) -> None:
    """Replace ``path`` with ``rows``, atomically."""
    with atomic_path(path) as tmp, tmp.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
