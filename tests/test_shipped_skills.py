"""The shipped skills' recipes: the 'shipped-skills' preset rebuilds each of them (``hrlp skills build``)."""

import shutil

import numpy as np
from typer.testing import CliRunner

from hrlp.arm.skill_files import shipped_library_root
from hrlp.cli import app
from hrlp.experiments.presets import PRESETS
from hrlp.experiments.skill_build import needs, stages
from hrlp.skills import SkillLibrary
from hrlp.train import TrainConfig


def test_every_shipped_skill_was_trained_by_its_recipe():
    preset, shipped = PRESETS["shipped-skills"], SkillLibrary(shipped_library_root())
    assert sorted(r.skill[0] for r in preset.runs) == shipped.names()
    for run in preset.runs:
        manifest = shipped.manifest(run.skill[0])
        assert TrainConfig.from_json(manifest["trained"]["config"]) == preset.config(run, 0), run.name
        assert manifest["k"] == run.skill[1] and manifest["trained"]["env_steps"] >= run.steps, run.name


def test_skills_build_trains_a_recipe_into_a_library_and_never_overwrites_unasked(tmp_path):
    lib, out = tmp_path / "lib", tmp_path / "runs"
    args = ["skills", "build", "--library", str(lib), "--out", str(out), "--only", "s-reacher", "--budget", "1000",
            "--workers", "1"]  # fmt: skip
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    manifest = SkillLibrary(lib).manifest("s-reacher")
    preset = PRESETS["shipped-skills"].with_budget(1000)
    run = next(r for r in preset.runs if r.name == "s-reacher")
    assert TrainConfig.from_json(manifest["trained"]["config"]) == preset.config(run, 0) and manifest["k"] == 15
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 2 and "already has s-reacher" in r.output
    r = CliRunner().invoke(app, [*args[:-4], "--only", "reachr"])
    assert r.exit_code == 2 and "no recipe for reachr" in r.output


def test_the_recipes_build_in_stages_each_after_the_skills_it_starts_from():
    order = {r.name: i for i, stage in enumerate(stages(PRESETS["shipped-skills"].runs)) for r in stage}
    assert order["gripper"] < order["mover-plain"] == order["mover-noised"]  # the grip bank is the Gripper's
    assert order["gripper-imitated"] < order["mover-held"]
    assert order["gripper-clearance"] < order["gripper-recovery"] < order["gripper-recovery-2"]  # weights and banks
    assert order["reacher"] == order["gripper"] == 0 and max(order.values()) == 2
    assert needs(next(r for r in PRESETS["shipped-skills"].runs if r.name == "gripper-recovery")) == (
        {"gripper-clearance"},
        ("recovery",),
    )


def test_skills_build_records_a_bank_from_the_librarys_own_skill_and_trains_from_it(tmp_path):
    lib, out = tmp_path / "lib", tmp_path / "runs"
    lib.mkdir()
    shutil.copytree(shipped_library_root() / "gripper-clearance", lib / "gripper-clearance")  # as an earlier build left it
    args = ["skills", "build", "--library", str(lib), "--out", str(out), "--only", "gripper-recovery", "--budget", "1000",
            "--workers", "1", "--bank-scale", "0.03"]  # fmt: skip
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    bank = lib / ".banks" / "gripper_recovery_starts.npz"
    assert f"recording the bank 'recovery' from gripper-clearance into {bank}" in r.output
    assert f"gripper-recovery starts from the bank {bank.resolve()}" in r.output.replace("\n", "")
    library = SkillLibrary(lib)
    assert library.names() == ["gripper-clearance", "gripper-recovery"]  # the bank's folder is not taken for a skill
    clearance = library.load("gripper-clearance").content_hash
    with np.load(bank, allow_pickle=False) as z:
        assert str(z["meta_skill_sha256"]) == clearance and len(z["handover_qpos"]) > 0
    assert library.manifest("gripper-recovery")["lineage"]["parent_sha256"] == clearance  # init_from: the library's
    again = CliRunner().invoke(app, [*args, "--overwrite"])  # the bank was recorded from this very skill: kept
    assert again.exit_code == 0 and "recording the bank" not in again.output, again.output
