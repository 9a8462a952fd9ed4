"""The Manager end to end: skills trained, frozen and loaded; hierarchical TRPO through the same loop; eval, render."""

import hashlib
import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from hrlp.arm import make
from hrlp.arm.skill_files import add_run
from hrlp.cli import app
from hrlp.config import MacroSpec, MicroAction
from hrlp.evaluate import evaluate_run
from hrlp.policies.mlp import HierarchicalPolicy
from hrlp.skills import SkillLibrary
from hrlp.skills.macro_env import MacroEnv, step_macros
from hrlp.train import TrainConfig, Trainer, load_trained, train


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    """Two tiny skills trained by the project's own loop, saved to a library on disk."""
    root = tmp_path_factory.mktemp("lib")
    lib = SkillLibrary(root / "skills")
    for task in ("Reacher", "Gripper"):
        list(train(TrainConfig(task=task, steps=200, batch_steps=200, num_envs=4, episode_steps=25), root / task))
        add_run(lib, root / task, task.lower(), k=5)
    return lib


def _weights_sha(lib, name):
    return hashlib.sha256((lib.root / name / "weights.safetensors").read_bytes()).hexdigest()


def _cfg(lib, **kw):
    spec = MacroSpec(("gripper", "reacher"), k=4, micro=MicroAction(duration=2), library=str(lib.root))
    base = dict(task="ReachAndGrip2", steps=600, batch_steps=24, num_envs=4, episode_steps=30, macro=spec, seed=3)
    return TrainConfig(**{**base, **kw})


def test_manager_trains_with_skills_frozen_and_its_batch_counts_low_level_steps(library, tmp_path):
    before = {n: _weights_sha(library, n) for n in ("gripper", "reacher")}
    skills_before = {n: [p.clone() for p in library.load(n).policy.parameters()] for n in before}
    stats = list(train(_cfg(library), tmp_path / "m"))
    assert len(stats) >= 2 and all(np.isfinite(s["trpo/kl"]) for s in stats)
    assert all(s["trpo/kl"] <= 1.5 * 0.01 for s in stats)  # the hierarchical trust region holds
    # Each decision lasts 2 (micro) or 4 (skills) low-level steps, or less at an episode's end.
    assert all(1 <= s["manager/mean_tau"] <= 4 for s in stats)
    assert stats[-1]["env_steps"] >= 600 and stats[0]["env_steps"] > 24
    # Skills are frozen: their files and their weights are unchanged by Manager training.
    assert {n: _weights_sha(library, n) for n in before} == before
    for n, params in skills_before.items():
        for p, q in zip(params, library.load(n).policy.parameters(), strict=True):
            assert torch.equal(p, q)
    meta = json.loads((tmp_path / "m" / "checkpoint" / "meta.json").read_text())["meta"]
    assert meta["kind"] == "manager" and meta["skills"] == {n: library.manifest(n)["sha256"] for n in before}
    trained = load_trained(tmp_path / "m")
    assert isinstance(trained.policy, HierarchicalPolicy) and trained.policy.param_dims == (0, 3, 9)
    ev = evaluate_run(tmp_path / "m", episodes=3)
    assert ev.success is not None and ev.macro_usage is not None
    assert set(ev.macro_usage) == {"gripper", "reacher", "micro"} and sum(ev.macro_usage.values()) == pytest.approx(1)


def test_manager_resume_is_exact(library, tmp_path):
    full = list(train(_cfg(library), tmp_path / "full"))
    part = list(train(_cfg(library, steps=200), tmp_path / "part"))
    rest = list(train(_cfg(library), tmp_path / "part", resume=True))
    assert len(part) + len(rest) == len(full)
    for a, b in zip(full, part + rest, strict=True):
        for key in ("return_mean", "trpo/kl", "trpo/surrogate_after", "env_steps"):
            assert a[key] == b[key] or (np.isnan(a[key]) and np.isnan(b[key])), key


def test_a_changed_skill_is_refused_on_resume(library, tmp_path):
    list(train(_cfg(library, steps=100), tmp_path / "m"))
    # Replace the reacher with a different one under the same name.
    list(train(TrainConfig(task="Reacher", steps=100, batch_steps=100, num_envs=2, episode_steps=20, seed=9), tmp_path / "r"))
    lib2 = SkillLibrary(tmp_path / "lib2")
    for n in ("gripper",):
        (lib2.root / n).mkdir(parents=True)
        for f in ("weights.safetensors", "meta.json"):
            (lib2.root / n / f).write_bytes((library.root / n / f).read_bytes())
    add_run(lib2, tmp_path / "r", "reacher", k=5)
    cfg = _cfg(library, steps=100)
    moved = TrainConfig.from_json({**cfg.to_json(), "macro": {**cfg.macro.to_json(), "library": str(lib2.root)}})
    trainer = Trainer(moved)
    with pytest.raises(ValueError, match="skill 'reacher' has changed since this Manager was trained"):
        from hrlp.train import check_skill_hashes

        saved = json.loads((tmp_path / "m" / "checkpoint" / "meta.json").read_text())["meta"]["skills"]
        check_skill_hashes(saved, trainer.skill_hashes, tmp_path / "m")


def test_batched_skill_inference_matches_one_environment_at_a_time(library):
    skills = [library.load("gripper"), library.load("reacher")]

    def envs():
        return [MacroEnv(make("ReachAndGrip2", episode_steps=30), skills, k=4, micro=MicroAction(3)) for _ in range(5)]

    batched, single = envs(), envs()
    for i, (a, b) in enumerate(zip(batched, single, strict=True)):
        a.reset(seed=i)
        b.reset(seed=i)
    rng = np.random.default_rng(0)
    for _ in range(8):
        actions = np.concatenate([rng.integers(0, 3, (5, 1)), rng.uniform(-1.2, 1.2, (5, 12))], axis=1)
        res = step_macros(batched, actions)
        for i, env in enumerate(single):
            blocks = (int(actions[i, 0]), actions[i, 1:1], actions[i, 1:4], actions[i, 4:13])
            obs, r, term, trunc, info = env.step(blocks)
            # Equal up to rounding: a matrix product over M rows may round differently from one over 1 row.
            np.testing.assert_allclose(res.obs[i], obs, rtol=1e-7, atol=1e-9)
            assert res.rewards[i] == pytest.approx(r, rel=1e-7) and res.tau[i] == info["tau"]
            assert res.discount[i] == info["discount"]
            assert (res.terminated[i], res.truncated[i]) == (term, trunc)
        for i in np.flatnonzero(res.terminated | res.truncated):
            batched[i].reset(seed=100 + int(i))
            single[i].reset(seed=100 + int(i))


def test_manager_actions_are_checked(library):
    env = MacroEnv(make("ReachAndGrip2", episode_steps=30), [library.load("reacher")], micro=MicroAction())
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(1, 13\)"):
        step_macros([env], np.zeros((1, 5)))
    with pytest.raises(ValueError, match="NaN or inf"):
        step_macros([env], np.full((1, 13), np.nan))
    with pytest.raises(ValueError, match=r"integers in \[0, 2\)"):
        step_macros([env], np.concatenate([[[2.0]], np.zeros((1, 12))], axis=1))
    with pytest.raises(ValueError, match="at least one skill or the micro-action"):
        MacroSpec(())


def test_cli_train_manager_eval_and_render_label_the_active_skill(library, tmp_path):
    runner = CliRunner()
    run = tmp_path / "m"
    args = ["train-manager", "ReachAndGrip2", "--skills", "gripper,reacher", "--micro", "--k", "3", "--library",
            str(library.root), "--steps", "300", "--batch-steps", "24", "--num-envs", "4", "--episode-steps", "20",
            "--run-dir", str(run)]  # fmt: skip
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, [*args[:-4], "--steps", "400", "--run-dir", str(run), "--resume"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["eval", str(run), "--episodes", "2"])
    assert r.exit_code == 0 and "decisions per macro-action" in r.output, r.output
    from hrlp.video import rollout_frames

    frames, _, name = rollout_frames(run, steps=12, width=96, height=72)
    frames = list(frames)
    assert "Manager" in name and len(frames) == 13

    # Every frame after the first carries the label: a dark box (20, 20, 20) with light text, top left.
    def labelled(f):
        corner = f[:24, :80]
        return (corner == 20).all(-1).sum() > 20 and (corner > 200).all(-1).any()

    assert all(labelled(f) for f in frames[1:]) and not labelled(frames[0])
    r = runner.invoke(app, ["train-manager", "ReachAndGrip2", "--skills", "nosuch", "--run-dir", str(tmp_path / "x")])
    assert r.exit_code == 2 and "no skill 'nosuch'" in r.output
    assert not (tmp_path / "x").exists()


def test_manager_trains_with_sampling_workers(library, tmp_path):
    stats = list(train(_cfg(library, workers=2, steps=200), tmp_path / "w"))
    assert stats[-1]["env_steps"] >= 200 and all(np.isfinite(s["trpo/kl"]) for s in stats)
    assert 1 <= stats[0]["manager/mean_tau"] <= 4
