"""Presets, the reproduction runner (process pool and Ray) and the tables, at tiny budgets."""

import json
import re
from dataclasses import replace
from pathlib import Path

import pytest
from typer.testing import CliRunner

from hrlp.cli import app
from hrlp.config import Handover
from hrlp.experiments.presets import PRESETS, RESEARCH_PRESETS, Preset, Run
from hrlp.experiments.runner import plan, reproduce, training_seconds
from hrlp.experiments.tables import bootstrap_interval, build_tables
from hrlp.fetch import check_installed
from hrlp.plots import read_progress
from hrlp.train import TrainConfig, env_factory


def _tiny(name="tiny"):
    cfg = TrainConfig(task="Reacher", batch_steps=60, num_envs=2, episode_steps=15)
    runs = (Run("normal", cfg, paper=0.5), Run("stabilised", TrainConfig(**{**cfg.__dict__, "task": "ReacherStabilised"})))
    return Preset(name, "two Reachers", "test", runs, seeds=(0, 1), budget=60, eval_episodes=2)


def test_every_preset_builds_valid_configs_with_distinct_run_names():
    for p in PRESETS.values():
        assert len({r.name for r in p.runs}) == len(p.runs), p.name
        own = {r.name: r.steps for r in p.runs}
        offset = {r.name: r.seed_offset for r in p.runs}
        for job in plan(p, __import__("pathlib").Path("out")):
            assert job.config.steps == (own[job.run] or p.budget) and job.seed in p.seeds
            assert job.config.seed == job.seed + offset[job.run]
        assert all(job.config.steps == 123 for job in plan(p.with_budget(123), __import__("pathlib").Path("out")))
    # Every environment a preset trains in can be built: its task arguments are valid and its skills are shipped.
    built = set()
    try:
        check_installed()
        fetch = True
    except ValueError:  # Gymnasium-Robotics' Fetch does not run on this MuJoCo (tests/fetch builds them where it does)
        fetch = False
    for p in PRESETS.values():
        for r in p.runs:
            c = r.config
            if c.task.startswith("gymnasium_robotics:Fetch") and not fetch:
                continue
            key = (c.task, c.macro, json.dumps(c.task_kwargs, sort_keys=True), c.episode_steps)
            if key not in built:
                env_factory(c.task, c.episode_steps, c.macro, c.advantage.gamma, **c.task_kwargs)().close()
                built.add(key)
    # Figure 6 is Experiment 1's Manager over the Gripper reward's grid ("Table 6 presents results of Experiment 1");
    # the paper gives no success rate for the flat Gripper.
    fig6 = {r.name: r.paper for r in PRESETS["reach-and-grip-1"].runs}
    assert fig6["gripper+reacher,c2=3,tr=0.03"] == 0.984 and fig6["gripper+reacher,c2=4,tr=0.06"] == 0.902
    assert {r.name: r.paper for r in PRESETS["reach-and-grip-1-tuned"].runs} == fig6
    assert all(r.config.macro.k == 10 and r.config.task == "ReachAndGrip1" for r in PRESETS["reach-and-grip-1"].runs)
    assert all(r.paper is None for r in PRESETS["gripper-grid"].runs)
    fig7 = {r.name: r.paper for r in PRESETS["reach-and-grip-2"].runs}
    assert fig7["gripper+micro,c2=3,tr=0.03"] == 0.86 and fig7["gripper+s-reacher,c2=4,tr=0.06"] == 0.70
    # The tuned grid differs from Figure 7's only in the Manager's batch and maximal KL, and its headline cell is
    # the headline preset's run.
    tuned = {r.name: r for r in PRESETS["reach-and-grip-2-tuned"].runs}
    assert {n: r.paper for n, r in tuned.items()} == fig7
    paper_cell = next(r for r in PRESETS["reach-and-grip-2"].runs if r.name == "gripper+reacher,c2=4,tr=0.06").config
    tuned_cell = tuned["gripper+reacher,c2=4,tr=0.06"].config
    assert (tuned_cell.batch_steps, tuned_cell.trpo.max_kl) == (2_000, 0.02)
    assert replace(tuned_cell, batch_steps=paper_cell.batch_steps, trpo=paper_cell.trpo) == paper_cell
    headline = next(r for r in PRESETS["headline"].runs if r.name == "manager:gripper+micro").config
    assert replace(tuned["gripper+micro,c2=3,tr=0.03"].config, task_kwargs={}) == headline
    # The hand-over grids differ from the tuned ones only in driving the Reacher for hand-over and the parameters'
    # initial spread; every preset without "handover" in its name runs its skills as the paper does.
    tuned_1 = {r.name: r.config for r in PRESETS["reach-and-grip-1-tuned"].runs}
    for name, base in (
        ("reach-and-grip-1-handover", tuned_1),
        ("reach-and-grip-2-handover", {n: r.config for n, r in tuned.items()}),
    ):
        runs = PRESETS[name].runs
        assert {r.name for r in runs} <= set(base) and not any(r.name.startswith("gripper+micro,") for r in runs)
        for r in runs:
            assert r.config.macro.handover == Handover() and r.config.init_log_std == -1.0, name
            assert replace(r.config, macro=replace(r.config.macro, handover=None), init_log_std=0.0) == base[r.name], name
            assert r.paper == (fig6 if "-1-" in name else fig7)[r.name]
    assert len(PRESETS["reach-and-grip-2-handover"].runs) == 12
    assert all(r.config.macro is None or r.config.macro.handover is None
               for p in PRESETS.values() if "handover" not in p.name
               and p.name not in ("reach-and-grip-1-samples", "reach-and-grip-2-imitated", "reach-and-grip-1-imitated",
                                 "reach-and-grip-1-claw", "reach-and-grip-2-claw", "reach-and-grip-2-clearance",
                                 "reach-and-grip-2-chained", "reach-and-grip-2-chained-recovery",
                                 "reach-and-grip-2-chained-recovery-2", "reach-and-move-imitated", "reach-and-move-chained",
                                 "reach-and-move-samples")
               for r in p.runs)  # fmt: skip
    # The imitated grid is the reacher-handover grid and the tuned gripper + micro cells with gripper-imitated in place
    # of the gripper, and nothing else.
    reacher_handover = {r.name: r.config for r in PRESETS["reach-and-grip-2-reacher-handover"].runs}
    imitated = PRESETS["reach-and-grip-2-imitated"].runs
    assert len(imitated) == 12
    for r in imitated:
        plain = r.name.replace("gripper-imitated", "gripper")
        base = reacher_handover.get(plain) or tuned[plain].config
        assert r.config.macro.skills == tuple(s.replace("gripper", "gripper-imitated") for s in base.macro.skills), r.name
        assert replace(r.config, macro=replace(r.config.macro, skills=base.macro.skills)) == base, r.name
        assert r.paper == fig7[plain.replace("reacher-handover", "reacher")], r.name
    # The claw grids are the imitated grids with gripper-claw in place of gripper-imitated, and Figure 7's also has
    # gripper + s-reacher as reach-and-grip-2-handover runs it, with gripper-claw.
    handover_2 = {r.name: r for r in PRESETS["reach-and-grip-2-handover"].runs}
    for claw, base_runs in (
        ("reach-and-grip-1-claw", PRESETS["reach-and-grip-1-imitated"].runs),
        ("reach-and-grip-2-claw", imitated),
    ):
        base = {r.name: r for r in base_runs}
        runs = PRESETS[claw].runs
        assert len(runs) == len(base) + (4 if "-2-" in claw else 0), claw
        for r in runs:
            other = (
                base.get(r.name.replace("gripper-claw", "gripper-imitated"))
                or handover_2[r.name.replace("gripper-claw", "gripper")]
            )
            assert r.config.macro.skills == tuple(s.replace(other.config.macro.skills[0], "gripper-claw", 1) if i == 0 else s
                                                  for i, s in enumerate(other.config.macro.skills)), r.name  # fmt: skip
            assert replace(r.config, macro=replace(r.config.macro, skills=other.config.macro.skills)) == other.config, r.name
            assert r.paper == other.paper, r.name
    # The clearance grid is Figure 7's claw grid with gripper-clearance in place of gripper-claw, and nothing else.
    claw_2 = {r.name: r for r in PRESETS["reach-and-grip-2-claw"].runs}
    clearance = PRESETS["reach-and-grip-2-clearance"].runs
    assert (
        len(clearance) == len(claw_2)
        and PRESETS["reach-and-grip-2-clearance"].budget == PRESETS["reach-and-grip-2-claw"].budget
    )
    for r in clearance:
        other = claw_2[r.name.replace("gripper-clearance", "gripper-claw")]
        assert r.config.macro.skills == tuple(
            s.replace("gripper-claw", "gripper-clearance") for s in other.config.macro.skills
        )
        assert replace(r.config, macro=replace(r.config.macro, skills=other.config.macro.skills)) == other.config, r.name
        assert r.paper == other.paper, r.name
    # The chained grid is the clearance grid's gripper + reacher cells with initiation sets and pre-grasp goals added.
    chained = PRESETS["reach-and-grip-2-chained"].runs
    plain = [r for r in clearance if r.name.startswith("gripper-clearance+reacher-handover,")]
    assert [r.name for r in chained] == [r.name + ",chained" for r in plain] and len(chained) == 4
    for r, other in zip(chained, plain, strict=True):
        h = r.config.macro.handover
        assert h.initiation and h.pregrasp and replace(h, initiation=False, pregrasp=False) == other.config.macro.handover
        assert replace(r.config, macro=replace(r.config.macro, handover=other.config.macro.handover)) == other.config
        assert r.paper == other.paper, r.name
    # ... and with gripper-recovery, or the second round's gripper-recovery-2, in gripper-clearance's place, nothing else.
    for preset, gripper in (("reach-and-grip-2-chained-recovery", "gripper-recovery"),
                            ("reach-and-grip-2-chained-recovery-2", "gripper-recovery-2")):  # fmt: skip
        recovery = PRESETS[preset].runs
        assert [r.name for r in recovery] == [r.name.replace("gripper-clearance", gripper) for r in chained], preset
        assert PRESETS[preset].budget == PRESETS["reach-and-grip-2-chained"].budget
        for r, other in zip(recovery, chained, strict=True):
            assert r.config.macro.skills == (gripper, "reacher-handover"), r.name
            assert replace(r.config, macro=replace(r.config.macro, skills=other.config.macro.skills)) == other.config, r.name
            assert r.paper == other.paper, r.name
    # reach-and-move with the imitated skills: reach (capsule-relative goals, the Reacher's own claw), grip, carry (the
    # Mover's target a world point), with the headline's Manager settings; TargetDistSum beside the paper's best pair.
    carry, carry_10 = PRESETS["reach-and-move-imitated"].runs
    assert carry.config.task == "ReachAndMove" and PRESETS["reach-and-move-imitated"].metric == "target_dist_sum"
    assert (
        carry.config.task_kwargs == {"target_coeff": 1}
        and replace(carry_10.config, task_kwargs={"target_coeff": 1}) == carry.config
    )
    assert carry.config.macro.skills == ("reacher-handover", "gripper-imitated", "mover-held") and carry.config.macro.k == 15
    assert carry.config.macro.handover == Handover(approach_height=0.0, open_torque=0.0, target_relative=True)
    assert (carry.config.batch_steps, carry.config.trpo.max_kl, carry.config.init_log_std) == (2_000, 0.02, -1.0)
    assert carry.paper == -41.470  # Figure 5's best cell, s-reacher + mover-noised
    # The chain with initiation sets: the same skills and paper cell, k = 50, pre-grasp goals, from the fast defaults.
    chained = PRESETS["reach-and-move-chained"].runs
    assert [r.name for r in chained] == [f"{r.name},chained" for r in (carry, carry_10)]
    for r, base in zip(chained, (carry, carry_10), strict=True):
        assert r.config.macro.skills == base.config.macro.skills and r.config.macro.k == 50 and r.paper == base.paper
        assert r.config.macro.handover == replace(base.config.macro.handover, initiation=True, pregrasp=True)
        assert (r.config.batch_steps, r.config.trpo.max_kl, r.config.init_log_std) == (600, 0.02, -2.0)
        assert r.config.task_kwargs == base.config.task_kwargs and r.config.backend == "batched"
    # Figure 6 with the imitated skills: each hand-over cell with reacher-handover (capsule-relative goals only) and
    # gripper-imitated in place of the paper's skills, and nothing else.
    for r in PRESETS["reach-and-grip-1-imitated"].runs:
        plain = r.name.replace("gripper-imitated+reacher-handover", "gripper+reacher")
        base = tuned_1[plain]
        assert r.config.macro.skills == ("gripper-imitated", "reacher-handover") and r.config.macro.k == 10, r.name
        assert r.config.macro.handover == Handover(approach_height=0.0, open_torque=0.0) and r.config.init_log_std == -1.0
        assert replace(r.config, macro=replace(base.macro, handover=None), init_log_std=0.0) == base, r.name
        assert r.paper == fig6[plain]
    # The samples preset's Manager is Figure 6's hand-over cell exactly (its runs can be shared); its flat run has the
    # paper's settings on the same task and reward.
    samples, fig6_handover = PRESETS["reach-and-grip-1-samples"], PRESETS["reach-and-grip-1-handover"]
    manager, flat = samples.runs
    cell = next(r for r in fig6_handover.runs if r.name == "gripper+reacher,c2=3,tr=0.03")
    assert samples.config(manager, 1) == fig6_handover.config(cell, 1) and manager.paper == cell.paper
    assert flat.config.macro is None and flat.config.task == "ReachAndGrip1"
    assert flat.config.task_kwargs == {"c2": 3, "tr": 0.03}
    assert (flat.config.batch_steps, flat.config.trpo.max_kl, samples.config(flat, 0).steps) == (50_000, 0.01, 3_000_000)
    # reach-and-move's samples preset: the chained Manager of reach-and-move-chained's TargetCoeff 1 cell (3M steps) and
    # reach-and-move-flat's TargetCoeff 1 run for 16M steps, so that their runs can be shared.
    names = ("reach-and-move-samples", "reach-and-move-chained", "reach-and-move-flat")
    rm_samples, rm_chained, rm_flat = (PRESETS[n] for n in names)
    rm_manager, rm_flat_run = rm_samples.runs
    cell = next(r for r in rm_chained.runs if r.name.endswith("target_coeff=1,chained"))
    assert rm_samples.config(rm_manager, 2) == rm_chained.config(cell, 2)
    assert rm_samples.config(rm_manager, 0).steps == 3_000_000
    flat_cell = next(r for r in rm_flat.runs if r.name == "target_coeff=1")
    assert rm_samples.config(rm_flat_run, 1) == replace(rm_flat.config(flat_cell, 1), steps=16_000_000)
    assert rm_samples.metric == "success" and {0.2, 0.5} <= set(rm_samples.thresholds or ())
    # Each tuned Appendix C sweep changes one setting of one cell of the tuned grid, and includes that cell itself.
    for name, base, setting in (
        ("manager-kl-tuned", "gripper+s-reacher", lambda c: c.trpo.max_kl),
        ("manager-k-tuned", "gripper+s-reacher", lambda c: c.macro.k),
        ("manager-size-tuned", "gripper+s-reacher", lambda c: c.hidden),
        ("micro-bounds-tuned", "gripper+reacher+micro", lambda c: c.macro.micro),
    ):
        cell = tuned[f"{base},c2=3,tr=0.03"].config
        configs = [r.config for r in PRESETS[name].runs]
        assert cell in configs and PRESETS[name].budget == PRESETS["reach-and-grip-2-tuned"].budget, name
        assert len({repr(setting(c)) for c in configs}) == len(configs), name
        for c in configs:
            if name == "manager-kl-tuned":
                c = replace(c, trpo=cell.trpo)
            elif name == "manager-size-tuned":
                c = replace(c, hidden=cell.hidden)
            else:
                c = replace(c, macro=cell.macro)
            assert c == cell, name


def test_runner_is_idempotent_resumable_and_tables_rebuild(tmp_path):
    preset = _tiny()
    first = reproduce(preset, tmp_path, workers=2)
    assert len(first) == 4 and not any(r.get("skipped") for r in first)
    result = json.loads((tmp_path / "tiny" / "normal" / "s1" / "result.json").read_text())
    assert result["seed"] == 1 and result["env_steps"] == 60 and 0 <= result["success"]["mean"] <= 1
    again = reproduce(preset, tmp_path, workers=2)
    assert all(r["skipped"] for r in again)
    # A bigger budget continues the finished runs from their checkpoints.
    more = reproduce(preset, tmp_path, budget=120, seeds=1, workers=2)
    assert len(more) == 2 and all(r["env_steps"] == 120 and not r.get("skipped") for r in more)
    # The wall time counts every training iteration, those before the continuation included.
    progress = read_progress(tmp_path / "tiny" / "normal" / "s0")
    assert len(progress["env_steps"]) == 2
    continued = next(r for r in more if r["run"] == "normal")
    assert continued["wall_s"] >= training_seconds(progress) > 0
    files = build_tables(tmp_path, tmp_path / "results")
    table = (tmp_path / "results" / "tiny.md").read_text()
    assert "| normal | 2 |" in table and "| 0.5 |" in table and any(f.suffix == ".png" for f in files)


def test_runner_copies_a_run_another_preset_finished_with_the_same_config(tmp_path):
    first = _tiny("first")
    reproduce(first, tmp_path, seeds=1, workers=1)
    # "second" shares the Reacher cell (same config, another run name) and adds one the first never ran.
    second = replace(
        first,
        name="second",
        runs=(replace(first.runs[0], name="same", paper=0.7), Run("other", replace(first.runs[0].config, hidden=(8, 8)))),
    )
    results = {r["run"]: r for r in reproduce(second, tmp_path, seeds=1, workers=1)}
    copied = results["same"]
    assert copied["copied_from"] == "first/normal/s0" and copied["preset"] == "second" and copied["paper"] == 0.7
    assert "copied_from" not in results["other"]
    original = json.loads((tmp_path / "first" / "normal" / "s0" / "result.json").read_text())
    on_disk = json.loads((tmp_path / "second" / "same" / "s0" / "result.json").read_text())
    assert on_disk == copied and on_disk["success"] == original["success"] and on_disk["config"] == original["config"]
    assert (tmp_path / "second" / "same" / "s0" / "checkpoint" / "weights.safetensors").is_file()
    assert not list((tmp_path / "second" / "same").glob("*.copying"))
    # A finished copy is skipped like any finished run; without reuse the cell is trained from scratch.
    assert all(r["skipped"] for r in reproduce(second, tmp_path, seeds=1, workers=1))
    third = replace(second, name="third")
    fresh = {r["run"]: r for r in reproduce(third, tmp_path, seeds=1, workers=1, reuse=False)}
    assert "copied_from" not in fresh["same"] and fresh["same"]["success"] == original["success"]
    # A copy of a copy names the run that was trained (with first's result hidden, second's copy is found first).
    hidden = tmp_path / "first" / "normal" / "s0" / "result.json"
    hidden.rename(hidden.with_suffix(".hidden"))
    fifth = {r["run"]: r for r in reproduce(replace(second, name="fifth", runs=second.runs[:1]), tmp_path, seeds=1)}
    assert fifth["same"]["copied_from"] == "first/normal/s0"
    hidden.with_suffix(".hidden").rename(hidden)
    # A different budget is a different run: nothing to copy.
    more = {r["run"]: r for r in reproduce(replace(second, name="fourth"), tmp_path, seeds=1, budget=120, workers=1)}
    assert "copied_from" not in more["same"] and more["same"]["env_steps"] == 120


def test_bootstrap_interval_and_bad_input(tmp_path):
    m, lo, hi = bootstrap_interval([0.2, 0.4, 0.6, 0.8])
    assert m == pytest.approx(0.5) and lo < m < hi
    assert bootstrap_interval([0.3]) == (0.3, 0.3, 0.3)
    r = CliRunner().invoke(app, ["reproduce", "nosuch", "--out", str(tmp_path)])
    assert r.exit_code == 2 and "unknown preset" in r.output
    r = CliRunner().invoke(app, ["reproduce", "reachers", "--backend", "dask", "--out", str(tmp_path)])
    assert r.exit_code == 2 and "--backend" in r.output
    r = CliRunner().invoke(app, ["tables", "--root", str(tmp_path / "none")])
    assert r.exit_code == 2 and "no finished runs" in r.output


@pytest.mark.extended  # starting Ray takes most of a minute: CI runs it in its extended pass
def test_ray_backend_runs_the_same_grid_on_a_local_ray_instance(tmp_path):
    ray = pytest.importorskip("ray")
    try:
        results = reproduce(_tiny("tiny-ray"), tmp_path, seeds=1, backend="ray")
    finally:
        ray.shutdown()
    assert len(results) == 2 and all((tmp_path / "tiny-ray" / r["run"] / "s0" / "result.json").exists() for r in results)


def test_a_run_with_an_imitation_stage_starts_from_the_student_and_is_never_confused_with_one_without(tmp_path):
    from hrlp.arm.research.imitate import ImitationConfig

    cfg = TrainConfig(task="Gripper", batch_steps=60, num_envs=2, episode_steps=15, workers=1)
    imitation = ImitationConfig(expert_episodes=2, dagger_rounds=0, epochs=1, minibatch=16)
    student = Preset("student", "imitated", "test", (Run("g", cfg, imitation=imitation),), seeds=(0,), budget=60,
                     eval_episodes=2)  # fmt: skip
    (result,) = reproduce(student, tmp_path, workers=1)
    run = tmp_path / "student" / "g" / "s0"
    assert result["imitation"] == json.loads(json.dumps(vars(imitation))) and result["env_steps"] == 60
    assert json.loads((run / "imitation.json").read_text())["rounds"][0]["states"] == 2 * 15  # two expert episodes
    # TRPO continued the student: its first logged iteration is the one after imitation's iteration 0.
    assert read_progress(run)["iteration"].tolist() == [1]
    # The same config without imitation is another run: trained, not copied; and the other way round.
    plain = {r["run"]: r for r in reproduce(replace(student, name="plain", runs=(Run("g", cfg),)), tmp_path, workers=1)}
    assert "copied_from" not in plain["g"] and plain["g"]["imitation"] is None
    again = {r["run"]: r for r in reproduce(replace(student, name="again"), tmp_path, workers=1)}
    assert again["g"]["copied_from"] == "student/g/s0"


def test_only_runs_the_runs_whose_names_match_and_a_pattern_that_matches_nothing_is_refused(tmp_path):
    results = reproduce(_tiny(), tmp_path, workers=1, only=("norm*",))
    assert sorted((r["run"], r["seed"]) for r in results) == [("normal", 0), ("normal", 1)]
    assert not (tmp_path / "tiny" / "stabilised").exists()
    with pytest.raises(ValueError, match=r"--only 'stab' matches no run of tiny \(runs: normal, stabilised\)"):
        reproduce(_tiny(), tmp_path, workers=1, only=("normal", "stab"))
    r = CliRunner().invoke(app, ["reproduce", "reach-and-grip-2", "--out", str(tmp_path), "--only", "gripper+nothing*"])
    assert r.exit_code == 2 and "--only 'gripper+nothing*' matches no run of reach-and-grip-2" in r.output, r.output


def test_the_docs_describe_every_preset_the_manual_its_own_and_the_research_record_the_rest():
    docs = Path(__file__).resolve().parents[1] / "docs"
    for page, names in (("reproduce.md", PRESETS.keys() - RESEARCH_PRESETS), ("research/presets.md", RESEARCH_PRESETS)):
        table = (docs / page).read_text().split("| preset | paper | runs |\n")[1].split("\n\n")[0]  # the presets' table
        rows = {n for line in table.splitlines() for n in re.findall(r"`([a-z0-9-]+)`", line.split("|")[1])}
        assert rows == set(names), f"docs/{page}: {sorted(rows ^ set(names))}"


def test_a_run_with_a_seed_offset_trains_each_seed_plus_it_in_the_seed_s_directory(tmp_path):
    cfg = TrainConfig(task="Reacher")
    preset = Preset("p", "", "", (Run("a", cfg), Run("b", cfg, seed_offset=200)), seeds=(0, 1))
    jobs = {(j.run, j.seed): j for j in plan(preset, tmp_path)}
    assert [jobs["a", s].config.seed for s in (0, 1)] == [0, 1] and [jobs["b", s].config.seed for s in (0, 1)] == [200, 201]
    assert jobs["b", 1].run_dir == tmp_path / "p" / "b" / "s1"
