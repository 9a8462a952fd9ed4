"""``hrlp theory``: run the search, save counterexamples, print one table per statement."""

from __future__ import annotations

import math
import pathlib
from dataclasses import replace

import rich.console
import rich.table
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.text import Text

from hrlp.theory.counterexample import save_counterexample
from hrlp.theory.search import SearchConfig, StatementSummary, search
from hrlp.theory.statements import STATEMENTS

DEFAULT_OUT_DIR = pathlib.Path("theory_counterexamples")


def _fmt(x: float | None) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return "inf" if math.isinf(x) else f"{x:.4g}"


def statement_table(summary: StatementSummary) -> rich.console.Group:
    """One table for one statement, under its name and formula: cases tried, held, smallest slack, counterexample."""
    verdict = "[green]holds on every case[/green]" if summary.holds else "[bold red]FAILS[/bold red]"
    heading = f"[bold]{escape(summary.label)}[/bold]: {verdict}"
    formula = summary.formula
    if summary.source == "corrected" and summary.corrects is not None:
        formula += f"   (replaces {STATEMENTS[summary.corrects].label})"
    elif summary.source == "variant" and summary.corrects is not None:
        formula += f"   (another reading of {STATEMENTS[summary.corrects].label})"
    table = rich.table.Table(show_header=False)
    table.add_column("quantity", style="bold")
    table.add_column("value", overflow="fold")
    table.add_row("cases tried", str(summary.cases))
    table.add_row("held", str(summary.held))
    if STATEMENTS[summary.name].relation == "==":
        table.add_row("largest |lhs − rhs|", _fmt(summary.max_abs_slack))
        table.add_row("largest |lhs − rhs| / tol", _fmt(summary.max_abs_slack_over_tol))
    else:
        table.add_row("smallest slack", _fmt(summary.min_slack))
        # +inf means no case had an allowance above round-off, so there is no ratio to show.
        relative = summary.min_relative_slack if summary.min_relative_slack != math.inf else None
        table.add_row("smallest slack / allowance", _fmt(relative))
    if summary.counterexample_size is None:
        table.add_row("counterexample", "none found")
    else:
        S, A = summary.counterexample_size
        table.add_row("counterexample", f"|S| = {S}, |A| = {A}, slack {_fmt(summary.counterexample_slack)}")
        table.add_row("saved to", str(summary.counterexample_path) if summary.counterexample_path is not None else "-")
    return rich.console.Group(Text.from_markup(heading), Text(formula), table)


def run_theory(
    mdps: int = 200,
    seed: int = 0,
    out_dir: pathlib.Path | None = None,
    console: rich.console.Console | None = None,
) -> list[StatementSummary]:
    """Search ``mdps`` random MDPs for violations of Section 3's statements and report them.

    Prints one table per statement to ``console`` (a new :class:`rich.console.Console` if ``None``), writes the
    smallest counterexample of every failing statement to ``out_dir/<statement>.json`` (default
    ``./theory_counterexamples``) and returns the summaries, in :data:`~hrlp.theory.statements.STATEMENTS` order.

    Raises:
        ValueError: if ``mdps <= 0``.
    """
    if isinstance(mdps, bool) or not isinstance(mdps, int) or mdps <= 0:
        raise ValueError(f"mdps must be a positive integer, got {mdps!r}")
    console = console if console is not None else rich.console.Console()
    out_dir = pathlib.Path(out_dir) if out_dir is not None else DEFAULT_OUT_DIR
    config = SearchConfig(mdps=mdps, seed=seed)
    with Progress(
        TextColumn("searching MDPs"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), console=console, transient=True
    ) as progress:
        task = progress.add_task("search", total=mdps)
        result = search(config, progress=lambda i: progress.update(task, completed=i + 1))
    summaries = []
    for summary in result.summaries:
        counterexample = result.counterexamples.get(summary.name)
        if counterexample is not None:
            path = save_counterexample(counterexample, out_dir / f"{summary.name}.json")
            summary = replace(summary, counterexample_path=path)
        summaries.append(summary)
        console.print(statement_table(summary))
        console.print()
    failing = [s.label for s in summaries if not s.holds]
    console.print(
        f"{len(summaries) - len(failing)} of {len(summaries)} statements held on every case"
        + (f"; failing: {', '.join(failing)}" if failing else "")
    )
    return summaries
