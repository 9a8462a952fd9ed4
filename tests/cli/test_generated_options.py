"""The options of ``hrlp train`` and ``hrlp train-manager`` are generated from the config dataclasses (issue 18): one
option per field of TrainConfig, AdvantageConfig, TRPOConfig, PPOConfig and ValueFitConfig (but those left out, with
their reasons), typed and defaulted by the field, its help the field's docstring; one list for both commands, checked
while parsed, reaching the config the trainer gets, compared on --resume, and ``--help`` stays torch-free."""

import ast
import dataclasses
import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

import hrlp.config
from hrlp.algos.trpo import TRPOConfig
from hrlp.algos.value import ValueFitConfig
from hrlp.cli import app
from hrlp.cli_params import BoundError, config_field
from hrlp.config import AdvantageConfig, PPOConfig, SACConfig
from hrlp.train import TrainConfig, read_run_checkpoint

CONFIGS = (TrainConfig, AdvantageConfig, TRPOConfig, PPOConfig, SACConfig, ValueFitConfig)
LEFT_OUT = {(TrainConfig, name) for name in ("task", "advantage", "trpo", "ppo", "sac", "value", "macro", "task_kwargs")}
"""The fields that are not generated options (cli._LEFT_OUT says why)."""
VALUE_FLAGS = {"max_iter": "--value-iters", "fraction": "--value-fraction", "l2_coef": "--value-l2-coef",
               "history_size": "--value-history-size"}  # fmt: skip
_SHARED_OWN = {"task", "run_dir", "task_arg", "resume", "paper_settings", "help"}
_MANAGER_OWN = {
    "skills",
    "micro",
    "micro_duration",
    "micro_penalty",
    "micro_max_torque",
    "k",
    "library",
    "handover",
    "handover_approach_height",
    "handover_open_torque",
    "handover_target_relative",
    "handover_initiation",
    "handover_pregrasp",
    "chain",
}
OWN = {"train": _SHARED_OWN, "train-manager": _SHARED_OWN | _MANAGER_OWN}
"""Each command's own parameters, beside the generated ones."""

# Every generated option set to a value other than its default, in a run that trains in seconds: (flag and its
# command-line value, or the flag alone for a switch) -> the value the config must hold.
SET = {
    (TrainConfig, "steps"): (("--steps", "40"), 40),
    (TrainConfig, "batch_steps"): (("--batch-steps", "20"), 20),
    (TrainConfig, "num_envs"): (("--num-envs", "4"), 4),
    (TrainConfig, "workers"): (("--workers", "2"), 2),
    (TrainConfig, "backend"): (("--backend", "serial"), "serial"),
    (TrainConfig, "seed"): (("--seed", "3"), 3),
    (TrainConfig, "episode_steps"): (("--episode-steps", "10"), 10),
    (TrainConfig, "hidden"): (("--hidden", "16,8"), (16, 8)),
    (TrainConfig, "init_log_std"): (("--init-log-std", "-0.5"), -0.5),
    (TrainConfig, "episodes"): (("--episodes", "1000"), 1000),
    (TrainConfig, "reward_scale"): (("--reward-scale", "2"), 2.0),
    (TRPOConfig, "max_kl"): (("--max-kl", "0.02"), 0.02),
    (TRPOConfig, "cg_iters"): (("--cg-iters", "5"), 5),
    (TRPOConfig, "cg_damping"): (("--cg-damping", "0.05"), 0.05),
    (TRPOConfig, "cg_residual_tol"): (("--cg-residual-tol", "1e-8"), 1e-8),
    (TRPOConfig, "line_search_backtracks"): (("--line-search-backtracks", "4"), 4),
    (TRPOConfig, "line_search_shrink"): (("--line-search-shrink", "0.6"), 0.6),
    (TrainConfig, "algo"): (("--algo", "ppo"), "ppo"),
    (AdvantageConfig, "gamma"): (("--gamma", "0.95"), 0.95),
    (AdvantageConfig, "gae_lambda"): (("--gae-lambda", "0.9"), 0.9),
    (TRPOConfig, "entropy_coef"): (("--entropy-coef", "0.01"), 0.01),
    (TRPOConfig, "normalize_advantages"): (("--no-normalize-advantages",), False),
    (TRPOConfig, "fisher_fraction"): (("--fisher-fraction", "0.5"), 0.5),
    (PPOConfig, "clip"): (("--ppo-clip", "0.3"), 0.3),
    (PPOConfig, "epochs"): (("--ppo-epochs", "2"), 2),
    (PPOConfig, "minibatches"): (("--ppo-minibatches", "4"), 4),
    (PPOConfig, "lr"): (("--ppo-lr", "1e-3"), 1e-3),
    (PPOConfig, "max_grad_norm"): (("--ppo-max-grad-norm", "1"), 1.0),
    (PPOConfig, "target_kl"): (("--ppo-target-kl", "0.05"), 0.05),
    (PPOConfig, "entropy_coef"): (("--ppo-entropy-coef", "0.01"), 0.01),
    (PPOConfig, "normalize_advantages"): (("--no-ppo-normalize-advantages",), False),
    (SACConfig, "lr"): (("--sac-lr", "1e-3"), 1e-3),
    (SACConfig, "batch_size"): (("--sac-batch-size", "64"), 64),
    (SACConfig, "buffer_size"): (("--sac-buffer-size", "5000"), 5000),
    (SACConfig, "learning_starts"): (("--sac-learning-starts", "10"), 10),
    (SACConfig, "updates_per_step"): (("--sac-updates-per-step", "0.5"), 0.5),
    (SACConfig, "tau"): (("--sac-tau", "0.01"), 0.01),
    (SACConfig, "hidden"): (("--sac-hidden", "32,32"), (32, 32)),
    (SACConfig, "init_alpha"): (("--sac-init-alpha", "0.2"), 0.2),
    (SACConfig, "choice_entropy"): (("--sac-choice-entropy", "0.3"), 0.3),
    (SACConfig, "her_future"): (("--sac-her-future", "2"), 2),
    (ValueFitConfig, "max_iter"): (("--value-iters", "5"), 5),
    (ValueFitConfig, "l2_coef"): (("--value-l2-coef", "0.01"), 0.01),
    (ValueFitConfig, "history_size"): (("--value-history-size", "5"), 5),
    (ValueFitConfig, "fraction"): (("--value-fraction", "0.5"), 0.5),
}

ELSEWHERE = {(TrainConfig, "init_from")}
"""Generated options set by a test of their own (a skill to start from fits no Pendulum run)."""


def _flag(config: type, field: str) -> str:
    if config is ValueFitConfig:
        return VALUE_FLAGS[field]
    prefix = {PPOConfig: "ppo-", SACConfig: "sac-"}.get(config, "")
    return f"--{prefix}{field.replace('_', '-')}"


def _listed() -> list[tuple[type, str]]:
    """Every field of the three configs that is not left out."""
    return [(c, f.name) for c in CONFIGS for f in dataclasses.fields(c) if (c, f.name) not in LEFT_OUT]


def _docstrings() -> dict[tuple[type, str], str]:
    """Each field's docstring read here from the source file of hrlp.config (the string right after the field)."""
    tree = ast.parse(Path(hrlp.config.__file__).read_text())
    classes = {c.__name__: c for c in CONFIGS}
    out = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name in classes:
            for a, b in zip(node.body, node.body[1:], strict=False):
                if isinstance(a, ast.AnnAssign) and isinstance(b, ast.Expr) and isinstance(b.value, ast.Constant):
                    out[(classes[node.name], a.target.id)] = " ".join(b.value.value.split())
    return out


@functools.cache
def _options(command: str) -> dict[str, typer.core.TyperOption]:
    """The parameters of ``hrlp COMMAND`` (typer's, built from the app as ``hrlp`` builds them) by name."""
    return {p.name: p for p in typer.main.get_command(app).commands[command].params}  # type: ignore[attr-defined]


def _option(command: str, flag: str) -> typer.core.TyperOption:
    return next(p for p in _options(command).values() if flag in p.opts)


def test_the_configs_are_the_ones_of_their_old_places():
    # Moved to hrlp.config (torch-free) and importable as before; a saved config reads back as the same class.
    from hrlp import algos, train

    assert train.TrainConfig is hrlp.config.TrainConfig and algos.TRPOConfig is hrlp.config.TRPOConfig
    assert algos.ValueFitConfig is hrlp.config.ValueFitConfig
    assert set(hrlp.config.field_docs(TRPOConfig)) == {f.name for f in dataclasses.fields(TRPOConfig)}


@pytest.mark.parametrize("command", ["train", "train-manager"])
def test_every_listed_field_is_an_option_typed_and_defaulted_by_it_with_its_docstring_as_help(command):
    docs = _docstrings()
    types = {
        "int": int,
        "float": float,
        "int | None": int,
        "bool": bool,
        "str": str,
        "str | None": str,
        "tuple[int, ...]": str,
    }  # W,W,... for widths
    for config, field in _listed():
        f = next(f for f in dataclasses.fields(config) if f.name == field)
        option = _option(command, _flag(config, field))
        assert option.help == docs[(config, field)], (command, field)
        assert option.help, (command, field)  # every listed field has a docstring
        default = 5_000 if (command, field) == ("train-manager", "batch_steps") else f.default
        assert option.type_descriptor.annotation is types[f.type], (command, field)
        if f.type == "bool":
            assert option.is_flag and option.secondary_opts == [f"--no-{_flag(config, field).removeprefix('--')}"]
            assert option.default is default
        elif f.type == "tuple[int, ...]":  # given as 64,64
            assert option.default == ",".join(map(str, default))
        else:
            assert option.default == default, (command, field)
    generated = {p.name for p in _options(command).values()} - OWN[command]
    assert len(generated) == len(_listed())  # no option beyond the fields and the command's own


def test_train_and_train_manager_share_the_generated_list():
    train, manager = _options("train"), _options("train-manager")
    shared = set(train) - OWN["train"]
    assert shared == set(manager) - OWN["train-manager"]
    for name in shared:
        a, b = train[name], manager[name]
        assert (a.opts, a.secondary_opts, a.help) == (b.opts, b.secondary_opts, b.help), name
        assert a.type_descriptor.annotation is b.type_descriptor.annotation, name
        assert a.default == b.default or name == "batch_steps"
    assert (train["batch_steps"].default, manager["batch_steps"].default) == (50_000, 5_000)
    # The commands' own options keep their names and short flags.
    assert train["task_arg"].opts == ["--task-arg"] and manager["k"].opts == ["--k"]


def test_a_fields_own_check_runs_while_parsing():
    # config_field: the dataclass refuses the value (here with no bounds of the CLI's before it), the option names it.
    param = _option("train", "--line-search-shrink")
    check = config_field(TRPOConfig, "line_search_shrink")
    assert check(param, 0.5) == 0.5
    with pytest.raises(BoundError, match=r"^--line-search-shrink must be in \(0, 1\), got 1\.0$"):
        check(param, 1.0)
    with pytest.raises(BoundError, match=r"^--value-fraction: value fraction must be in \(0, 1\], got 2\.0$"):
        config_field(ValueFitConfig, "fraction")(_option("train", "--value-fraction"), 2.0)


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (("--line-search-shrink", "1"), "--line-search-shrink must be in (0, 1), got 1"),
        (("--line-search-backtracks", "0"), "--line-search-backtracks must be a positive integer, got 0"),
        (("--cg-residual-tol", "-1"), "--cg-residual-tol must be >= 0, got -1"),
        (("--max-kl", "0"), "--max-kl must be > 0, got 0"),
        (("--entropy-coef", "-0.1"), "--entropy-coef must be >= 0, got -0.1"),
        (("--value-history-size", "0"), "--value-history-size must be a positive integer, got 0"),
        (("--value-l2-coef", "nan"), "--value-l2-coef must be a finite number, got nan"),
        (("--hidden", "64,0"), "--hidden must be positive layer widths separated by commas, e.g. 64,64, got '64,0'"),
        (("--init-log-std", "inf"), "--init-log-std must be a finite number, got inf"),
    ],
)
def test_a_bad_value_is_one_line_while_parsing(args, line, tmp_path):
    for command in ("train", "train-manager"):
        r = CliRunner().invoke(app, [command, "Reacher", *args, "--run-dir", str(tmp_path / "r")])
        assert r.exit_code == 2 and r.output.strip().splitlines() == [f"error: {line}"], r.output
    assert not (tmp_path / "r").exists()


def test_every_option_set_on_the_command_line_reaches_the_trainers_config_and_resume_compares_it(tmp_path):
    assert set(SET) | ELSEWHERE == set(_listed())  # a new field needs a value here
    args = [a for flag_and_value, _ in SET.values() for a in flag_and_value]
    run = tmp_path / "run"
    r = CliRunner().invoke(app, ["train", "Pendulum-v1", *args, "--run-dir", str(run)])
    assert r.exit_code == 0, r.output
    saved = read_run_checkpoint(run / "checkpoint")[2]  # the config the trainer ran with
    for (config, field), (_, value) in SET.items():
        holder = {TrainConfig: saved, AdvantageConfig: saved.advantage, TRPOConfig: saved.trpo, PPOConfig: saved.ppo,
                  SACConfig: saved.sac, ValueFitConfig: saved.value}[config]  # fmt: skip
        assert getattr(holder, field) == value, field
    assert saved == TrainConfig.from_json(json.loads((run / "config.json").read_text()))
    # A resume refuses a new value of any of them, naming it; the same values (or none) continue the run.
    again = CliRunner().invoke(app, ["train", "Pendulum-v1", "--run-dir", str(run), "--resume", "--line-search-shrink",
                                     "0.7", "--hidden", "32", "--normalize-advantages", "--value-l2-coef",
                                     "0.01"])  # fmt: skip
    assert again.exit_code == 2, again.output
    line = " ".join(again.output.split())
    assert "--line-search-shrink 0.7 (the run: 0.6)" in line and "--hidden 32 (the run: 16,8)" in line
    assert "--normalize-advantages True (the run: False)" in line and "--value-l2-coef" not in line
    more = CliRunner().invoke(app, ["train", "Pendulum-v1", "--run-dir", str(run), "--resume", "--steps", "60",
                                    "--cg-residual-tol", "1e-8", "--hidden", "16,8"])  # fmt: skip
    assert more.exit_code == 0, more.output
    resumed = read_run_checkpoint(run / "checkpoint")[2]
    assert resumed == dataclasses.replace(saved, steps=60)


def test_a_manager_gets_the_generated_options(tmp_path):
    r = CliRunner().invoke(app, ["train-manager", "ReachAndGrip2", "--micro", "--steps", "8", "--batch-steps", "4",
                                 "--num-envs", "2", "--episode-steps", "8", "--line-search-backtracks", "3", "--hidden",
                                 "8", "--value-history-size", "4", "--run-dir", str(tmp_path / "m")])  # fmt: skip
    assert r.exit_code == 0, r.output
    cfg = TrainConfig.from_json(json.loads((tmp_path / "m" / "config.json").read_text()))
    assert cfg.macro is not None and cfg.macro.micro is not None and cfg.batch_steps == 4
    assert (cfg.trpo.line_search_backtracks, cfg.hidden, cfg.value.history_size) == (3, (8,), 4)


@pytest.mark.parametrize("command", ["train", "train-manager"])
def test_command_help_is_torch_free_and_lists_every_generated_option(command):
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", "hrlp", command, "--help"], capture_output=True,
                       text=True, timeout=60, env={**os.environ, "COLUMNS": "250"})  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    imported = {line.rsplit("|", 1)[-1].strip().split(".")[0] for line in r.stderr.splitlines()
                if line.startswith("import time:")}  # fmt: skip
    assert not imported & {"torch", "mujoco", "gymnasium"}, imported & {"torch", "mujoco", "gymnasium"}
    for config, field in _listed():
        assert _flag(config, field) in r.stdout, field
    assert "Trust-region radius delta" in r.stdout  # a docstring, as help


GRIPPER_ARGS = ["--task-arg", "c3=-8", "--task-arg", "c4=10", "--task-arg", "finger_opening=[0.0,1.0]", "--task-arg",
                "start_distance=[0.0,0.09]"]  # fmt: skip
"""The shipped gripper's training task arguments (its manifest's ``trained.config``)."""


def test_init_from_starts_a_flat_run_from_a_skill_and_resume_keeps_it(tmp_path):
    from hrlp.skills.library import load_skill

    run = tmp_path / "ft"
    tiny = ["--steps", "20", "--batch-steps", "10", "--num-envs", "2", "--workers", "1", "--episode-steps", "10"]
    r = CliRunner().invoke(app, ["train", "Gripper", "--init-from", "gripper", *GRIPPER_ARGS, *tiny, "--run-dir", str(run)])
    assert r.exit_code == 0, r.output
    saved = read_run_checkpoint(run / "checkpoint")[2]
    assert saved.init_from == "gripper" and saved.hidden == (64, 64)
    # It started from the skill: after two small TRPO steps its weights are still near the skill's, far from a fresh net.
    tensors = read_run_checkpoint(run / "checkpoint")[0]
    skill = load_skill("gripper").policy.state_dict()
    first = next(k for k in skill if k.endswith("weight"))
    assert float((tensors[f"policy.{first}"] - skill[first]).abs().max()) < 0.05
    # Frozen, it records the skill it started from, with the hash that skill had.
    from hrlp.arm.skill_files import add_run
    from hrlp.skills.library import SkillLibrary

    lib = SkillLibrary(tmp_path / "lib")
    add_run(lib, run, "gripper-more")
    assert lib.manifest("gripper-more")["lineage"] == {
        "parent": "gripper",
        "parent_sha256": load_skill("gripper").content_hash,
    }
    again = CliRunner().invoke(app, ["train", "Gripper", "--run-dir", str(run), "--resume", "--init-from", "reacher"])
    assert again.exit_code == 2 and "--init-from reacher (the run: gripper)" in " ".join(again.output.split())


@pytest.mark.parametrize(
    ("command", "args", "line"),
    [
        ("train", ["--init-from", "."], "--init-from .: neither a skill directory (with meta.json) nor a skill name"),
        ("train-manager", ["--skills", "gripper", "--init-from", "gripper"],
         "--init-from starts a flat run from a skill's weights; a Manager starts from a fresh network (its skills are "
         "given by --skills)"),
        ("train", ["--init-from", "gripper-claw"],
         "init_from: skill gripper-claw (Gripper, 45 observations) does not fit a Gripper run with 24 observations; it "
         "was trained on Gripper with --task-arg c3=-8 --task-arg c4=10 --task-arg finger_opening=[0.0,1.0] --task-arg "
         "observe_capsule=true --task-arg observe_claw=true --task-arg start_distance=[0.0,0.09] --hidden 256,256"),
    ],
)  # fmt: skip
def test_init_from_that_cannot_start_the_run_is_one_line_before_anything_is_written(command, args, line, tmp_path):
    task = "ReachAndGrip2" if command == "train-manager" else "Gripper"
    r = CliRunner().invoke(app, [command, task, *args, "--steps", "20", "--run-dir", str(tmp_path / "r")])
    assert r.exit_code != 0 and " ".join(r.output.split()) == f"error: {line}", r.output
    assert not (tmp_path / "r").exists()


def test_a_run_started_from_a_skill_directory_resumes_after_the_skill_is_gone(tmp_path):
    import shutil

    from hrlp.arm.skill_files import shipped_library_root

    parent = tmp_path / "mine" / "gripper"
    shutil.copytree(shipped_library_root() / "gripper", parent)
    run = tmp_path / "ft"
    tiny = ["--steps", "20", "--batch-steps", "10", "--num-envs", "2", "--workers", "1", "--episode-steps", "10"]
    r = CliRunner().invoke(app, ["train", "Gripper", "--init-from", str(parent), *GRIPPER_ARGS, *tiny, "--run-dir", str(run)])
    assert r.exit_code == 0, r.output
    sha = read_run_checkpoint(run / "checkpoint")[1]["init_from_sha256"]
    shutil.rmtree(parent)  # the weights now come from the run's checkpoint; the skill it started from is its lineage
    more = CliRunner().invoke(app, ["train", "Gripper", "--run-dir", str(run), "--resume", "--steps", "40"])
    assert more.exit_code == 0, more.output
    _, meta, cfg = read_run_checkpoint(run / "checkpoint")
    assert meta["env_steps"] >= 40 and meta["init_from_sha256"] == sha and cfg.init_from == str(parent)
