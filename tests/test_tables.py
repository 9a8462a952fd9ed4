"""The table builder's sweep scatters and sample-efficiency table: known answers on synthetic curves and runs."""

import csv
import json
import math

import numpy as np
import pytest

from hrlp.experiments.presets import PRESETS
from hrlp.experiments.runner import run_dir_name
from hrlp.experiments.tables import (
    Crossing,
    build_tables,
    censored_median,
    format_steps,
    grid_lines,
    iqm_cell,
    iqm_interval,
    run_crossings,
    sample_efficiency_lines,
    smoothed_rate,
    speedup,
    steps_to_threshold,
    sweep_x,
)
from hrlp.plots import plot_sweep

NAN = math.nan


def test_smoothed_rate_needs_a_full_window_skips_empty_iterations_and_weights_by_episodes():
    s = smoothed_rate(np.array([0.0, 0.0, 0.3, 0.0, 0.0]), window=3)
    assert np.isnan(s[:2]).all() and s[2:] == pytest.approx([0.1, 0.1, 0.1])
    # An iteration where no episode ended (NaN) is left out of its windows.
    assert smoothed_rate(np.array([NAN, NAN, NAN, 0.5]), window=3)[3] == 0.5
    assert np.isnan(smoothed_rate(np.array([NAN, NAN, NAN]), window=3)).all()
    # Weighted by episodes: 0 of 3 and 1 of 1 episodes succeeded -> 1/4.
    assert smoothed_rate(np.array([0.0, 1.0]), np.array([3.0, 1.0]), window=2)[1] == 0.25
    with pytest.raises(ValueError, match="window"):
        smoothed_rate(np.zeros(3), window=0)


def test_steps_to_threshold_crosses_at_the_known_step_and_ignores_one_lucky_iteration():
    steps = np.arange(1, 9) * 1000.0
    rate = np.array([0.0, 0.0, 0.0, 0.1, 0.2, 0.3, 0.3, 0.3])
    # Trailing means from iteration 3 on: 0, 1/30, 0.1, 0.2, ... -> first >= 0.15 at the 6th iteration.
    assert steps_to_threshold(steps, rate, 0.15) == 6000.0
    assert steps_to_threshold(steps, rate, 0.15, window=1) == 5000.0
    lucky = np.array([0.0, 0.0, 0.0, 0.4, 0.0, 0.0, 0.0, 0.0])
    assert steps_to_threshold(steps, lucky, 0.2, window=1) == 4000.0
    assert steps_to_threshold(steps, lucky, 0.2) is None  # smoothed, it peaks at 0.133


def test_censored_median_is_exact_only_when_censored_seeds_cannot_move_it():
    assert censored_median([100, 200, 300], [True] * 3) == (200, True)
    # 2 of 3 reached, the third is censored at 1000 (its true value is larger): the median is still 200.
    assert censored_median([100, 200, 1000], [True, True, False]) == (200, True)
    # 1 of 3 reached: the median is only bounded below, by the budget.
    assert censored_median([100, 1000, 1000], [True, False, False]) == (1000, False)
    # 2 of 4 reached: (200 + T) / 2 with T > 1000, so 600 is a lower bound, not the median.
    assert censored_median([100, 200, 1000, 1000], [True, True, False, False]) == (600, False)
    # A seed censored early (at 150, e.g. a shorter run) could still cross before 200.
    assert censored_median([100, 200, 150], [True, True, False]) == (150, False)
    assert censored_median([1000], [False]) == (1000, False)
    with pytest.raises(ValueError):
        censored_median([], [])


def test_crossing_cells_report_mean_median_or_lower_bound_with_the_count_of_seeds():
    assert Crossing((100_000.0, 200_000.0, 300_000.0), (True,) * 3).cell().startswith("200k [")
    assert Crossing((100_000.0, 200_000.0, 300_000.0), (True,) * 3).cell().endswith("(3/3)")
    assert Crossing((1.5e6,), (True,)).cell() == "1.5M (1/1)"
    assert Crossing((100_000.0, 200_000.0, 1e6), (True, True, False)).cell() == "median 200k (2/3, rest > 1M)"
    assert Crossing((100_000.0, 1e6, 1e6), (True, False, False)).cell() == "≥ 1M (1/3, rest > 1M)"
    assert Crossing((1e6, 1e6), (False, False)).cell() == "≥ 1M (0/2)"
    assert Crossing((100_000.0, 1e6), (True, False)).cell() == "≥ 550k (1/2, rest > 1M)"  # (100k + T) / 2, T > 1M
    assert format_steps(950) == "950" and format_steps(12_500) == "12.5k" and format_steps(NAN) == "-"


def test_speedup_says_which_way_censoring_bounds_the_ratio():
    man = Crossing((100.0, 200.0, 300.0), (True,) * 3)
    flat = Crossing((1000.0, 2000.0, 3000.0), (True,) * 3)
    never = Crossing((3000.0, 3000.0, 3000.0), (False,) * 3)
    assert speedup(man, flat) == (10.0, "=")
    assert speedup(man, never) == (15.0, ">=")
    assert speedup(never, flat) == (2000.0 / 3000.0, "<=")
    assert speedup(never, never) is None


def test_run_crossings_censor_each_seed_at_its_own_final_step_count():
    steps = np.array([1000.0, 2000.0, 3000.0, 4000.0])
    good = {"env_steps": steps, "success_rate": np.array([0.2, 0.2, 0.2, 0.2]), "episodes": np.ones(4)}
    bad = {"env_steps": steps[:3], "success_rate": np.zeros(3), "episodes": np.ones(3)}
    no_column = {"env_steps": steps}
    (c,) = run_crossings([good, bad, no_column], [0.1])
    assert c.steps == (3000.0, 3000.0, 4000.0) and c.reached == (True, False, False)


def _log(cross_at: float | None, budget: float, step: float = 100_000.0) -> dict[str, np.ndarray]:
    steps = np.arange(step, budget + step / 2, step)
    return {"env_steps": steps, "success_rate": (steps >= (cross_at or math.inf)).astype(float)}


def test_best_runs_are_chosen_so_that_censoring_never_inflates_the_manager_advantage():
    runs = {
        "man-known": (True, [_log(500_000, 600_000)] * 3),  # median 500k, exact
        "man-censored": (True, [_log(100_000, 600_000), _log(None, 400_000), _log(None, 400_000)]),  # >= 400k only
        "flat-known": (False, [_log(2e6, 3e6)] * 3),  # median 2M, exact
        "flat-censored": (False, [_log(None, 1e6)] * 3),  # >= 1M only: could be faster than flat-known
    }
    lines = sample_efficiency_lines(runs, thresholds=(0.5,), window=1)
    assert "| man-censored | Manager | 3 | ≥ 400k (1/3, rest > 400k) |" in lines
    assert lines[-1] == (
        "- success 50%: `man-known` 500k (3/3) vs `flat-censored` ≥ 1M (0/3): the Manager needs at least 2x fewer environment "
        "steps."
    )


def test_sweep_x_reads_the_swept_value_from_each_presets_configs():
    def xs(preset):
        p = PRESETS[preset]
        return {r.name: sweep_x(preset, p.config(r, 0).to_json()) for r in p.runs}

    assert xs("reach-and-move-flat") == {f"target_coeff={c}": c for c in (1, 2, 5, 10)}
    alphas = xs("reach-and-grip-2-flat")  # run alpha=pi*A/1e5 -> 10^5 * alpha = pi * A
    assert alphas["alpha=pi*10/1e5"] == pytest.approx(math.pi * 10) and alphas["alpha=pi*0.1/1e5"] == pytest.approx(
        math.pi * 0.1
    )
    assert xs("reach-and-grip-2-flat-kl") == {"max_kl=0.001": 0.001, "max_kl=0.01": 0.01, "max_kl=0.1": 0.1}
    assert xs("manager-k") == {"k=5": 5, "k=10": 10, "k=15": 15, "k=25": 25}
    assert xs("manager-size") == {"hidden=32": 32, "hidden=64": 64, "hidden=128": 128}
    assert set(xs("manager-kl").values()) == {0.003, 0.01, 0.03}
    assert xs("manager-kl-tuned") == {"max_kl=0.005": 0.005, "max_kl=0.02": 0.02, "max_kl=0.08": 0.08}
    assert xs("manager-k-tuned") == {"k=5": 5, "k=10": 10, "k=15": 15, "k=25": 25}
    assert xs("manager-size-tuned") == {"hidden=32": 32, "hidden=64": 64, "hidden=128": 128}
    assert sweep_x("headline", {}) is None and sweep_x("manager-k", {"macro": None}) is None


def _write_run(root, preset, run, seed, success, rates, steps_per_iter=10_000):
    """A finished run as runner.py lays it out: result.json (full config) and progress.csv."""
    p = PRESETS[preset]
    r = next(r for r in p.runs if r.name == run)
    d = root / preset / run_dir_name(run) / f"s{seed}"
    d.mkdir(parents=True)
    with (d / "progress.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["iteration", "env_steps", "episodes", "return_mean", "success_rate", "target_dist_sum"])
        for i, rate in enumerate(rates, 1):
            w.writerow([i, i * steps_per_iter, 10, -100 + i, rate, "nan"])
    result = {
        "preset": preset,
        "run": run,
        "seed": seed,
        "config": p.config(r, seed).to_json(),
        "env_steps": len(rates) * steps_per_iter,
        "wall_s": 60.0,
        "episodes": 100,
        "success": {"mean": success, "low": max(0.0, success - 0.1), "high": min(1.0, success + 0.1)},
        "return": {"mean": -50.0, "low": -60.0, "high": -40.0},
        "target_dist_sum": None,
        "macro_usage": None,
        "paper": r.paper,
    }
    (d / "result.json").write_text(json.dumps(result))


def test_build_tables_writes_the_sweep_scatter_and_the_sample_efficiency_table(tmp_path):
    root, out = tmp_path / "runs", tmp_path / "results"
    for i, a in enumerate((0.1, 1, 10, 100)):
        for seed in (0, 1):
            _write_run(root, "reach-and-grip-2-flat", f"alpha=pi*{a:g}/1e5", seed, 0.1 * i + 0.05 * seed, [0.0, 0.1, 0.2])
    ramp = [0.0, 0.0, 0.3, 0.3, 0.3, 0.3]  # smoothed: -, -, 0.1, 0.2, 0.3 -> reaches 0.05 and 0.1 at 30k, 0.2 at 40k
    for seed in (0, 1, 2):
        _write_run(root, "headline", "manager:gripper+micro", seed, 0.8, ramp)
        _write_run(root, "headline", "flat", seed, 0.0, [0.0] * 6)  # never: censored at 60k
    files = build_tables(root, out)
    scatter = out / "reach-and-grip-2-flat_scatter.png"
    assert scatter in files and scatter.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (out / "headline_scatter.png").exists()  # no swept parameter
    md = (out / "headline.md").read_text()
    assert "## Sample efficiency" in md and "| steps to 5% | steps to 10% | steps to 20% |" in md
    assert "| manager:gripper+micro | Manager | 3 | 30k [30k, 30k] (3/3) | 30k [30k, 30k] (3/3) | 40k [40k, 40k] (3/3) |" in md
    assert "| flat | flat | 3 | ≥ 60k (0/3) | ≥ 60k (0/3) | ≥ 60k (0/3) |" in md
    assert "- success 10%: `manager:gripper+micro` 30k (3/3) vs `flat` ≥ 60k (0/3): the Manager needs at least 2x fewer" in md
    sweep_md = (out / "reach-and-grip-2-flat.md").read_text()
    assert "reach-and-grip-2-flat_scatter.png" in sweep_md and "| alpha=pi*0.1/1e5 | flat | 2 |" in sweep_md
    assert "Best Manager" not in sweep_md  # no Manager runs in this preset
    # Thresholds are a parameter; a single one gives a single column.
    build_tables(root, out, thresholds=(0.25,), window=1)
    assert "| steps to 25% |" in (out / "headline.md").read_text()
    with pytest.raises(ValueError, match="thresholds"):
        build_tables(root, out, thresholds=(1.5,))
    # A preset that declares its own thresholds gets them unless the caller gives some.
    for seed in (0, 1):
        _write_run(root, "reach-and-grip-1-samples", "manager:gripper+reacher", seed, 1.0, [0.0, 0.3, 0.6, 0.9, 1.0, 1.0])
    build_tables(root, out, window=1, overwrite=True)
    samples = (out / "reach-and-grip-1-samples.md").read_text()
    assert "| steps to 5% | steps to 20% | steps to 50% | steps to 90% |" in samples
    assert "| steps to 5% | steps to 10% | steps to 20% |" in (out / "headline.md").read_text()
    build_tables(root, out, thresholds=(0.25,), window=1)
    assert "| steps to 25% |" in (out / "reach-and-grip-1-samples.md").read_text()
    with pytest.raises(ValueError, match="must end in"):
        plot_sweep([(1.0, [0.5])], out / "scatter.txt", "x", "y")


def test_a_success_preset_on_reach_and_move_shows_what_the_capsule_did(tmp_path):
    root, out = tmp_path / "runs", tmp_path / "results"
    manager = "manager:reacher-handover+gripper-imitated+mover-held,chained"
    _write_run(root, "reach-and-move-samples", manager, 0, 0.9, [0.1, 0.6, 0.9])
    _write_run(root, "reach-and-move-samples", "flat", 0, 0.0, [0.0, 0.0, 0.0])
    result_path = root / "reach-and-move-samples" / run_dir_name(manager) / "s0" / "result.json"
    result = json.loads(result_path.read_text())
    interval = {"low": 0.0, "high": 1.0}
    result["move"] = {"lift_rate": {"mean": 0.95, **interval}, "min_target_dist": {"mean": 0.012, **interval},
                      "relative_target_dist_sum": {"mean": 15.3, **interval},
                      "untouched_target_dist_sum": {"mean": -45.0, **interval}}  # fmt: skip
    result_path.write_text(json.dumps(result))
    build_tables(root, out)
    md = (out / "reach-and-move-samples.md").read_text()
    assert "| success / lifted / min d(C, T) / TargetDistSum minus untouched |" in md
    assert "| 0.9 / 0.95 / 0.012 m / +15.3 (untouched -45.0) |" in md  # the Manager's row
    assert "| flat | 1 | 0 [0, 0.1] | 0 | - | 30,000 | 0.02 | - |" in md.splitlines()  # no move record: '-'
    # A success preset whose runs recorded no capsule moves has no such column.
    _write_run(root, "headline", "flat", 0, 0.0, [0.0, 0.0])
    build_tables(root, out)
    assert "TargetDistSum minus untouched" not in (out / "headline.md").read_text()


def test_grid_lines_lay_runs_out_as_the_papers_figure():
    lines = grid_lines({"a,c2=3,tr=0.03": ("0.5", 0.86), "a,c2=4,tr=0.06": ("0.25", None), "b,c2=3,tr=0.03": ("0", 0.1)})
    assert lines == [
        "| | c2=3, tr=0.03 | c2=4, tr=0.06 |",
        "|---|---|---|",
        "| a | 0.5 (0.86) | 0.25 |",
        "| b | 0 (0.1) |  |",
    ]
    with pytest.raises(ValueError, match="ROW,COLUMN"):
        grid_lines({"no-comma": ("0", None)})


def test_manager_tables_show_skill_usage_and_mark_copied_runs(tmp_path):
    root, out = tmp_path / "runs", tmp_path / "results"
    for seed, usage in ((0, {"gripper": 0.7, "reacher": 0.1, "micro": 0.2}), (1, {"gripper": 0.5, "micro": 0.5})):
        _write_run(root, "micro-bounds-tuned", "free", seed, 0.2, [0.1, 0.2])
        path = root / "micro-bounds-tuned" / "free" / f"s{seed}" / "result.json"
        path.write_text(json.dumps({**json.loads(path.read_text()), "macro_usage": usage, "copied_from": "other/x/s0"}))
    _write_run(root, "micro-bounds-tuned", "duration=5", 0, 0.3, [0.1, 0.2])
    _write_run(root, "reachers", "Reacher", 0, 0.9, [0.1, 0.2])
    build_tables(root, out)
    md = (out / "micro-bounds-tuned.md").read_text()
    assert "| decisions per skill (mean over seeds) |" in md and "Runs marked * were copied from `other`" in md
    assert "| free* | 2 |" in md and md.count("| gripper 60%, reacher 5%, micro 35% |") == 1
    row = next(line for line in md.splitlines() if line.startswith("| duration=5 |"))  # the main table comes first
    assert row.endswith("| 0.02 | - |")  # wall time, then no usage recorded
    flat = (out / "reachers.md").read_text()
    assert "decisions per skill" not in flat and "copied" not in flat


def test_figure_7_presets_get_the_grid_layout(tmp_path):
    root, out = tmp_path / "runs", tmp_path / "results"
    _write_run(root, "reach-and-grip-2-tuned", "gripper+micro,c2=3,tr=0.06", 0, 0.875, [0.1, 0.5])
    _write_run(root, "reach-and-grip-2-tuned", "gripper+reacher,c2=3,tr=0.03", 0, 0.25, [0.1, 0.2])
    build_tables(root, out)
    md = (out / "reach-and-grip-2-tuned.md").read_text()
    assert "| | c2=3, tr=0.06 | c2=3, tr=0.03 |" in md
    assert "| gripper+micro | 0.875 (0.74) |  |" in md and "| gripper+reacher |  | 0.25 (0.17) |" in md


def test_iqm_is_the_mean_of_the_middle_half_with_a_seeded_bootstrap_interval():
    m, lo, hi = iqm_interval([8, 1, 7, 2, 6, 3, 5, 4])  # sorted 1..8: the middle half 3, 4, 5, 6
    assert m == 4.5 and 1 <= lo < m < hi <= 8
    assert iqm_interval(list(range(1, 9))) == (m, lo, hi)  # the same values, the same interval: tables are reproducible
    assert iqm_interval([1, 2, 3, 100])[0] == 2.5  # an outlier seed is cut, unlike in the mean (26.5)
    assert iqm_interval([0.1, 0.2, 0.4])[0] == pytest.approx(0.7 / 3)  # fewer than 4 seeds: nothing cut, the mean
    assert iqm_interval([0.4, 0.4, 0.4, 0.4]) == (0.4, 0.4, 0.4)  # all equal: a zero-width interval
    assert iqm_interval([0.3]) == (0.3, 0.3, 0.3)  # one seed: the value, a zero-width interval
    assert all(math.isnan(v) for v in iqm_interval([]))
    m, lo, hi = iqm_interval([0.0, 1.0])
    assert (m, lo, hi) == (0.5, 0.0, 1.0)  # resamples of two seeds: both 0, mixed, both 1
    assert iqm_cell([0.3]) == "0.3" and iqm_cell([]) == "-" and iqm_cell([1, 2, 3, 100]).startswith("2.5 [")


def test_tables_show_the_iqm_beside_the_mean(tmp_path):
    root, out = tmp_path / "runs", tmp_path / "results"
    for seed, success in enumerate((0.1, 0.2, 0.3, 0.9)):  # mean 0.375, IQM 0.25
        _write_run(root, "reachers", "Reacher", seed, success, [0.1, 0.2])
    _write_run(root, "reachers", "ReacherStabilised", 0, 0.5, [0.1, 0.2])  # one seed: its own Wilson interval, one IQM
    build_tables(root, out)
    md = (out / "reachers.md").read_text()
    assert "| run | seeds | ours | IQM | paper |" in md and "interquartile mean" in md
    _, lo, hi = iqm_interval([0.1, 0.2, 0.3, 0.9])
    assert lo < 0.25 < hi
    row = next(line for line in md.splitlines() if line.startswith("| Reacher |"))
    assert row.startswith("| Reacher | 4 | 0.375 [") and f"] | 0.25 [{lo:.3g}, {hi:.3g}] | " in row
    assert next(line for line in md.splitlines() if line.startswith("| ReacherStabilised |")).startswith(
        "| ReacherStabilised | 1 | 0.5 [0.4, 0.6] | 0.5 | "
    )


def test_iqm_of_real_tiny_runs_and_tables_rebuilt_byte_for_byte(tmp_path):
    from hrlp.experiments.presets import Preset, Run
    from hrlp.experiments.runner import reproduce
    from hrlp.train import TrainConfig

    cfg = TrainConfig(task="Reacher", batch_steps=16, num_envs=2, episode_steps=8)
    preset = Preset("tiny-iqm", "a Reacher", "test", (Run("normal", cfg),), seeds=(0, 1, 2, 3), budget=16, eval_episodes=3)
    results = reproduce(preset, tmp_path, workers=1)
    out = tmp_path / "results"
    build_tables(tmp_path, out)
    first = (out / "tiny-iqm.md").read_bytes()
    row = next(line for line in first.decode().splitlines() if line.startswith("| normal |"))
    values = [r["success"]["mean"] for r in sorted(results, key=lambda r: r["seed"])]
    assert row.split(" | ")[3] == iqm_cell(values)
    build_tables(tmp_path, out)  # unchanged runs: the same bytes, the bootstrap included
    assert (out / "tiny-iqm.md").read_bytes() == first
