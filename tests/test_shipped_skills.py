"""The shipped skills' recipes: the 'shipped-skills' preset rebuilds each of them (``hrlp skills build``)."""

from typer.testing import CliRunner

from hrlp.arm.skill_files import shipped_library_root
from hrlp.cli import app
from hrlp.experiments.presets import PRESETS
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
