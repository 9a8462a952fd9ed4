"""Every benchmark script runs end to end at a tiny budget (their figures come from full runs; see docs/benchmarks.md)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.extended  # CI runs them in a pass of their own (.ci/run); the default suite stays short

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"

CASES = {  # script: (arguments, a line its output must contain)
    "gripper_diagnosis.py": ("--skill gripper-imitated --episodes 2 --steps 30", "success by start clearance (the arm's"),
    "backend_returns.py": ("--steps 32 --batch-steps 32 --num-envs 4 --seeds 1 --episodes 1", "batched: return"),
    "eval_speed.py": ("--episodes 3 --steps 40 --batch-steps 40 --num-envs 4", "same results: True"),
    "env_step.py": ("--steps 200 --repeats 1 --tasks Reacher,Gripper", "median env/physics time ratio"),
    "stability.py": ("--steps 200 --tasks Reacher", "unstable episodes"),
    "manager_speed.py": ("--rounds 1 --flat-batch 400 --manager-batch 40 --num-envs 8", "Manager / flat: sampling"),
    "trpo_speed.py": (
        "--steps 1000 --batch-steps 500 --arm-steps 500 --physics-steps 300 --workers 1 --defaults-batch-steps 500 "
        "--skip sb3,tianshou,rss",
        "mj_step share of 1 core(s) x wall: measured in the run",
    ),
    "trpo_returns.py": (
        "--libs hrlp --hrlp paper,defaults --steps 1000 --batch-steps 500 --seeds 1 --episodes 1",
        "hrlp-defaults",
    ),
    "reliability.py": ("--only physics --blow-ups 2", "forced physics blow-ups: 24 (3 kinds x 2 steps x 4 tasks"),
    "carry_plan.py": ("--episodes 2 --initiation", "k = 15, initiation sets: success"),
    "chain_exploration.py": ("--episodes 2 --k 100 --policy mover", "policy mover, k = 100, log-std -2, initiation sets on"),
    "scripted_grasp.py": ("--episodes 2 --steps 30 --no-bank --first-version", "episodes; capsule pushed > 3 cm in"),
    "batched_step.py": ("--world-steps 40 --episode-steps 30 --repeats 1 --n 4", "fastest:"),
    "ppo_vs_trpo.py": (  # its flat path trains as test_ppo.py's PPO run does
        "--only manager --workers 1 --seeds 1 --manager-steps 32 --manager-batch 32 --episodes 1 --out cmp",
        "| ppo | 32 |",
    ),
}


def _run(script: str, args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCH / script), *args.split()], capture_output=True, text=True, cwd=cwd,
                          timeout=300)  # fmt: skip


#: The scripts behind docs/benchmarks.md's goals: each records its run as a dated file (benchmarks/runlog.py).
RECORDED = {"manager_speed.py", "trpo_speed.py", "trpo_returns.py", "batched_step.py"}


@pytest.mark.parametrize("script", sorted(CASES))
def test_benchmark_script_runs(script, tmp_path):
    args, expected = CASES[script]
    out = _run(script, args, tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert expected in out.stdout, out.stdout[-2000:]
    if script in RECORDED:
        (run,) = (tmp_path / "benchmarks" / "runs").glob(f"{Path(script).stem}-*.json")
        doc = json.loads(run.read_text())
        assert doc["script"] == script and doc["command"].startswith(f"python benchmarks/{script} ") and doc["figures"]
        assert (
            doc["versions"]["hrlp"]
            and doc["machine"]["cpus"] >= 1
            and f"run recorded in {run.relative_to(tmp_path)}" in out.stdout
        )


def test_manager_vs_flat_runs_and_reuses_finished_runs(tmp_path):
    args = f"--steps 300 --seeds 1 --workers 1 --episodes 1 --flat-batch 400 --out {tmp_path / 'cmp'}"
    first = _run("manager_vs_flat.py", args, tmp_path)
    assert first.returncode == 0, first.stderr[-2000:]
    assert (tmp_path / "cmp" / "manager-s0" / "checkpoint").exists() and (tmp_path / "cmp" / "flat-s0").exists()
    again = _run("manager_vs_flat.py", args, tmp_path)
    assert again.returncode == 0 and again.stdout == first.stdout


def test_gripper_variants_retrains_the_shipped_gripper_and_reports_both_start_sets(tmp_path):
    from hrlp.arm import make
    from hrlp.arm.research.starts import write_start_bank
    from hrlp.arm.tasks import HANDOVER_BANK

    env = make("Gripper")
    env.reset(seed=0)
    d = env.physics.data
    write_start_bank(tmp_path / "bank.npz", {HANDOVER_BANK: (d.qpos[None].copy(), d.qvel[None].copy())}, {"test": "1"})
    args = f"--bank {tmp_path / 'bank.npz'} --variant axis+push --steps 1 --episodes 1 --workers 1 --out {tmp_path / 'v'}"
    out = _run("gripper_variants.py", args, tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "axis+push, 1 steps, from handover starts: success" in out.stdout and "from own starts" in out.stdout
    config = __import__("json").loads((tmp_path / "v" / "skill" / "config.json").read_text())
    assert config["task_kwargs"]["distance"] == "axis" and config["task_kwargs"]["push_coeff"] == 10.0
    assert config["init_from"].endswith("gripper")
    assert "from paper_default starts: success" in out.stdout
    # --evaluate: a finished run of any recipe, nothing trained; an existing results.json is never replaced.
    out = _run("gripper_variants.py", f"--bank {tmp_path / 'bank.npz'} --episodes 1 --evaluate {tmp_path / 'v' / 'skill'} "
               f"--graspable 0.2 0.1 --out {tmp_path / 'e'}", tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    assert "1 of 1 states with d(H, C) <= 0.2 m" in out.stdout
    assert set(__import__("json").loads((tmp_path / "e" / "results.json").read_text())) == {
        "handover", "own", "paper_default", "graspable_handover"}  # fmt: skip
    again = _run("gripper_variants.py", f"--bank {tmp_path / 'bank.npz'} --evaluate {tmp_path / 'v' / 'skill'} "
                 f"--out {tmp_path / 'e'}", tmp_path)  # fmt: skip
    assert again.returncode == 2 and "exists" in again.stderr


def test_gripper_handover_collects_four_banks_and_evaluates_every_start_set(tmp_path):
    manager = subprocess.run([sys.executable, "-m", "hrlp", "train-manager", "ReachAndGrip2", "--skills",
                              "gripper-imitated,reacher-handover", "--steps", "200", "--batch-steps", "20", "--num-envs",
                              "2", "--workers", "1", "--run-dir", str(tmp_path / "m")], capture_output=True, text=True,
                             timeout=300)  # fmt: skip
    assert manager.returncode == 0, manager.stderr[-2000:]
    args = f"{tmp_path / 'm'} --states 2 --episodes 1 --steps 20 --out {tmp_path / 'gh'}"
    out = _run("gripper_handover.py", args, tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    results = __import__("json").loads((tmp_path / "gh" / "results.json").read_text())
    assert set(results["gripper-imitated"]) == {"own", "paper", "all", "not_held", "initiation_not_held", "switch_not_held"}
    for bank in ("all", "not_held", "initiation_not_held", "switch_not_held"):
        assert f"bank {bank}: 2 hand-over states" in out.stdout and (tmp_path / "gh" / f"{bank}.npz").is_file()
    from hrlp.arm import make
    from hrlp.arm.tasks import SparseSuccess, start_bank
    from hrlp.skills import load_skill

    env = make("Gripper")
    env.reset(seed=0)
    physics, initiation = env.unwrapped.physics, load_skill("gripper-imitated").initiation
    for q, v in zip(*start_bank(str(tmp_path / "gh" / "initiation_not_held.npz")), strict=True):
        physics.set_state_vectors(q, v)
        physics.forward()
        assert not SparseSuccess()(physics)
        assert initiation.holds(np.concatenate([np.zeros(18), physics.hand, physics.capsule])[None])[0]
    again = _run("gripper_handover.py", args, tmp_path)
    assert again.returncode == 2 and "exists" in again.stderr


@pytest.mark.parametrize(
    ("bank", "args", "skill"),
    [
        ("recovery", "", "gripper-clearance"),
        ("recovery-2", "--skill gripper-recovery --first-seed 1000000", "gripper-recovery"),
    ],
)
def test_gripper_recovery_writes_the_first_states_of_the_shipped_recovery_banks(tmp_path, bank, args, skill):
    from importlib import resources

    from hrlp.arm.skill_files import shipped_library_root
    from hrlp.arm.tasks import GRIPPER_BANKS, gripper_start_bank, start_bank
    from hrlp.mjcompat import free_body_spin_as_4_0
    from hrlp.skills import SkillLibrary

    out = _run("gripper_recovery.py", f"{args} --episodes 60 --out {tmp_path / 'b.npz'}", tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    qpos, qvel = start_bank(str(tmp_path / "b.npz"))
    shipped_qpos, shipped_qvel = gripper_start_bank(bank)
    assert 0 < len(qpos) < len(shipped_qpos)  # the command's first 60 episodes: a prefix of the shipped bank's 3,000
    assert np.isfinite(qpos).all() and np.isfinite(qvel).all()
    with np.load(resources.files("hrlp.arm").joinpath(GRIPPER_BANKS[bank])) as z:  # recorded from this skill
        assert str(z["meta_skill_sha256"]) == SkillLibrary(shipped_library_root()).load(skill).content_hash
    again = _run("gripper_recovery.py", f"--episodes 1 --out {tmp_path / 'b.npz'}", tmp_path)
    assert again.returncode != 0 and "exists" in again.stderr
    if not free_body_spin_as_4_0():  # MuJoCo 3.3: the banks' pushed capsules spin under another rule (hrlp.mjcompat)
        pytest.skip("the shipped bank was recorded on a MuJoCo that integrates a spinning free body as 3.11 and 4.0 do")
    # The shipped bank was simulated on another machine: MuJoCo's last digits differ between CPUs (up to 1e-11 here).
    np.testing.assert_allclose(qpos, shipped_qpos[: len(qpos)], rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(qvel, shipped_qvel[: len(qvel)], rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("clearance", [False, True], ids=["escape", "escape-and-clearance"])
def test_claw_escape_builds_gripper_claws_recipe_with_the_escape_expert(tmp_path, clearance):
    import json

    from hrlp.experiments.presets import PRESETS

    args = "--out cmp --steps 500 --expert-episodes 2 --noisy-expert-episodes 0 --dagger-rounds 0 --eval-episodes 0"
    out = _run("claw_escape.py", args + " --observe-clearance" * clearance, tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    name = "gripper-claw-clearance" if clearance else "gripper-claw-escape"
    assert f"{name}: 25,024 TRPO steps, greedy success" in out.stdout
    result = json.loads((tmp_path / "cmp" / "claw-escape" / name / "s0" / "result.json").read_text())
    assert result["imitation"]["expert_escape_clearance"] == 0.01
    recipe = next(r for r in PRESETS["shipped-skills"].runs if r.name == "gripper-claw")
    # gripper-claw's run, the expert aside (and the arm's distances to the capsule observed with --observe-clearance)
    extra = {"observe_clearance": True} if clearance else {}
    assert result["config"]["task_kwargs"] == {**recipe.config.task_kwargs, **extra}
    assert tuple(result["config"]["hidden"]) == tuple(recipe.config.hidden)


def test_trpo_speed_refuses_a_baseline_checkout_without_hrlp_before_training(tmp_path):
    out = _run("trpo_speed.py", f"--baseline-checkout {tmp_path} --steps 1000", tmp_path)
    assert out.returncode == 1 and out.stdout == ""
    assert (
        out.stderr.strip() == f"--baseline-checkout {tmp_path}: not an hrlp checkout (no benchmarks/trpo_speed.py, src/hrlp)"
    )

    out = _run("trpo_speed.py", f"--baseline-checkout {tmp_path} --skip arm", tmp_path)
    assert out.returncode == 1 and out.stdout == ""
    assert out.stderr.strip() == "--baseline-checkout compares the ReachAndGrip2 rows; it cannot go with --skip arm"


def test_checkout_ab_runs_each_checkout_and_refuses_a_directory_without_hrlp(tmp_path):
    out = _run("checkout_ab.py", f"{BENCH.parent} --task Reacher --steps 1 --rounds 1", tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert f"round 1, {BENCH.parent}: " in out.stdout and "of the cores, TRPO step" in out.stdout
    bad = _run("checkout_ab.py", str(tmp_path), tmp_path)
    assert bad.returncode != 0 and "not an hrlp checkout" in bad.stderr
    task = _run("checkout_ab.py", f"{BENCH.parent} --task NoSuchTask --steps 1 --rounds 1", tmp_path)
    assert task.returncode != 0 and len(task.stderr.strip().splitlines()) == 1 and "the run failed: " in task.stderr
