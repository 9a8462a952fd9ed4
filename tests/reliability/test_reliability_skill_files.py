"""Skill files from someone else: only regular files within bounds are read, the manifest is checked against the tensors
before anything is allocated, names stay inside the library, degenerate skills are refused at load naming the skill,
`skills list` survives a broken entry, and a checkpoint's meta is checked key by key (docs/reliability.md, items 10-14).

The bad files are real files (FIFOs, links to /dev/zero, safetensors, JSON, pickles) built by
``bad_skill_files.build_bad_skill_files``; the commands that could hang or exhaust memory on a careless reader run
through the real ``hrlp`` in forked processes with a deadline and an address-space limit (``run_bad_skill_files``).
"""

import json
import shutil

import pytest
import torch
from bad_skill_files import GOOD, MODES, BadSkillFiles, Outcome, build_bad_skill_files, code_executed, run_bad_skill_files
from typer.testing import CliRunner

from hrlp.arm.skill_files import add_run, shipped_library_root
from hrlp.checkpoint import META_FILE, WEIGHTS_FILE, CheckpointError, ReadLimits, load_checkpoint, save_checkpoint
from hrlp.cli import app
from hrlp.skills import SkillLibrary, load_skill
from hrlp.train import TrainConfig, load_policy, train

#: Kinds also loaded the way a Manager loads its skills (``hrlp train-manager --skills``); every kind goes through
#: ``hrlp skills show``, which makes the same checks (the benchmark runs every kind both ways).
LOAD_KINDS = ("weights-fifo", "meta-fifo", "weights-dev-zero", "meta-huge", "meta-deep", "obs-dim-huge", "hidden-huge",
              "block-misfit", "weights-nan", "weights-int", "k-fraction", "entry-linked-outside", "name-parent",
              "name-absolute", "weights-pickle")  # fmt: skip
#: The arm's shipped skills (hrlp.arm's library), and every domain's (Fetch's fetch-reach too).
ARM_SHIPPED = ("gripper", "gripper-claw", "gripper-clearance", "gripper-imitated", "gripper-recovery", "gripper-recovery-2",
               "mover-held", "mover-noised", "mover-plain", "reacher", "reacher-handover", "reacher3d",
               "s-reacher")  # fmt: skip
SHIPPED = tuple(sorted(("fetch-reach", *ARM_SHIPPED)))


@pytest.fixture(scope="module")
def bad(tmp_path_factory) -> BadSkillFiles:
    return build_bad_skill_files(tmp_path_factory.mktemp("bad-skills"))


@pytest.fixture(scope="module")
def outcomes(bad) -> dict[tuple[str, str], Outcome]:
    """Every kind through ``skills show``, LOAD_KINDS through ``train-manager``, the control, and ``skills list``."""
    extra = [("good", ["skills", "show", GOOD, "--library", str(bad.library)]),
             ("list", ["skills", "list", "--library", str(bad.library)])]  # fmt: skip
    runs = run_bad_skill_files(bad, {"show": None, "load": LOAD_KINDS}, deadline=8.0, extra=extra)
    return {(o.kind, o.mode): o for o in runs}


def _assert_refused(bad: BadSkillFiles, outcome: Outcome) -> None:
    case = next(c for c in bad.cases if c.kind == outcome.kind)
    said = f"{case.kind} ({outcome.mode}): exit {outcome.returncode}, {outcome.stdout[-300:]!r} {outcome.stderr[-600:]!r}"
    assert not outcome.hung, said
    assert outcome.clean_error, said
    line = outcome.error_lines[0]
    assert case.expect in line, said
    assert (f"skill {case.arg!r}" if case.entry else f"skill name {case.arg!r}") in line, said  # the skill named


def test_forty_kinds_of_bad_skill_files_are_refused_in_one_line_without_a_hang_a_traceback_or_code_run(bad, outcomes):
    assert len(bad.cases) >= 40 and len({c.kind for c in bad.cases}) == len(bad.cases)
    ran = [o for (_, mode), o in outcomes.items() if mode in MODES]
    assert {o.kind for o in ran} == {c.kind for c in bad.cases}
    assert {o.kind for o in ran if o.mode == "load"} == set(LOAD_KINDS)
    for outcome in ran:
        _assert_refused(bad, outcome)
    assert code_executed(bad) == []  # no pickle payload, Python file or manifest string ever ran
    good = outcomes[("good", "extra")]  # the control: the harness tells a good skill from a bad one
    assert good.returncode == 0 and '"sha256": "f26de9e88be2' in good.stdout, good.stderr


def test_fifos_devices_huge_and_deep_files_are_refused_before_they_are_read(bad, outcomes):
    """A FIFO used to hang the reader, /dev/zero to be read until memory ran out, a 100 MB manifest to be accepted and
    a deep one to raise RecursionError; now each is one line, at once (Manager loading included)."""
    kinds = ("weights-fifo", "meta-fifo", "entry-fifo", "weights-dev-zero", "meta-dev-zero", "weights-dev-urandom",
             "weights-huge", "meta-huge", "meta-deep", "meta-deep-20", "weights-header-deep")  # fmt: skip
    for kind in kinds:
        for mode in MODES:
            if (kind, mode) in outcomes:
                _assert_refused(bad, outcomes[(kind, mode)])
                assert outcomes[(kind, mode)].seconds < 4.0, outcomes[(kind, mode)]


def test_manifest_numbers_are_checked_against_the_tensors_before_a_network_is_allocated(bad, outcomes):
    """``obs_dim: 10000000`` used to allocate 5 GB (and ``hidden: [100000, 100000]`` 40 GB) before the shape check;
    under the harness's address-space limit that was a MemoryError traceback. Now the manifest is checked first."""
    for kind in ("obs-dim-huge", "hidden-huge", "hidden-other", "hidden-deeper", "block-misfit", "normalizer-misfit"):
        _assert_refused(bad, outcomes[(kind, "show")])
    for kind in ("obs-dim-huge", "hidden-huge", "block-misfit"):
        _assert_refused(bad, outcomes[(kind, "load")])
    with pytest.raises(CheckpointError, match=r"policy\.mean_net\.0\.bias has shape \[64\] in its weights, \[100000\]"):
        SkillLibrary(bad.library).load("hidden-huge")


def test_show_refuses_names_that_are_not_plain_entry_names(tmp_path, monkeypatch):
    monkeypatch.setenv("HRLP_SKILLS", str(tmp_path / "user"))
    library, beside = tmp_path / "lib", tmp_path / "beside"
    shutil.copytree(shipped_library_root() / "reacher", library / "mine")
    shutil.copytree(shipped_library_root() / "reacher", beside)
    runner = CliRunner()
    for name in ("../beside", str(beside), "mine/../../beside", "..", "."):
        r = runner.invoke(app, ["skills", "show", name, "--library", str(library)])
        assert r.exit_code == 2, (name, r.output)
        assert r.output.startswith(f"error: skill name {name!r} is not a plain entry name"), (name, r.output)
        assert '"sha256"' not in r.output  # nothing from outside the library was printed
        with pytest.raises(ValueError, match="not a plain entry name"):
            load_skill(name, library)
    assert runner.invoke(app, ["skills", "show", "mine", "--library", str(library)]).exit_code == 0


@pytest.mark.parametrize(
    ("kind", "problem"),
    [
        ("weights-nan", r"policy\.mean_net\.0\.weight holds NaN or inf \(27 of 1728 values\)"),
        ("weights-inf", r"policy\.mean_net\.4\.bias holds NaN or inf"),
        ("normalizer-nan", r"normalizer\.mean holds NaN or inf"),
        ("normalizer-negative-var", r"normalizer\.var is negative"),
        ("weights-int", r"policy\.mean_net\.0\.weight is 'I32'; a skill's weights must be floating point"),
        ("weights-bool", r"policy\.mean_net\.2\.weight is 'BOOL'; a skill's weights must be floating point"),
        ("k-fraction", r"manifest's 'k' \(default duration\) must be an integer from 1 to 10,000, got 1\.5 \(float\)"),
        ("k-bool", r"manifest's 'k' .* got True \(bool\)"),
        ("k-zero", r"manifest's 'k' .* got 0 \(int\)"),
        ("k-negative", r"manifest's 'k' .* got -3 \(int\)"),
        ("block-misfit", r"policy\.mean_net\.0\.weight has shape \[64, 26\] in its weights, \[64, 27\]"),
        ("extra-tensor", r"its weights do not fit the network .*\): unexpected policy\.mean_net\.6\.weight$"),
        ("entry-linked-outside", r"a symbolic link out of the library"),
    ],
)
def test_degenerate_skills_are_refused_at_load_naming_the_skill(bad, kind, problem):
    with pytest.raises(ValueError, match=rf"^skill '{kind}' \(.*\): {problem}") as info:
        SkillLibrary(bad.library).load(kind)
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match=rf"^skill '{kind}'"):  # the way a Manager loads its skills
        load_skill(kind, bad.library)


def test_the_shipped_skills_still_load_and_act():
    lib = SkillLibrary(shipped_library_root())
    assert lib.names() == list(ARM_SHIPPED)
    for name in ARM_SHIPPED:
        skill = lib.load(name)
        recorded = json.loads((shipped_library_root() / name / META_FILE).read_text())["sha256"]
        assert skill.content_hash == recorded and skill.k in (8, 15)
        features = torch.zeros(2, skill.feature_dim).numpy() if skill.features else None
        torques = skill.torques(torch.zeros(2, 24).numpy(), torch.zeros(2, skill.param.dim).numpy(), features)
        assert torques.shape == (2, 9) and bool(torch.isfinite(torch.from_numpy(torques)).all())


def test_skills_list_marks_a_broken_entry_and_lists_the_rest(bad, outcomes):
    r = outcomes[("list", "extra")]
    assert r.returncode == 0 and not r.traceback, r.stderr[-2000:]
    rows = {line.split()[0]: line for line in r.stdout.splitlines()[2:] if line.strip()}  # after the title and header
    assert "Reacher" in rows[GOOD] and "library" in rows[GOOD] and "broken" not in rows[GOOD]
    for name in SHIPPED:
        assert "shipped" in rows[name] and "broken" not in rows[name]
    entries = [c.kind for c in bad.cases if c.entry]
    for kind in entries:
        assert "broken" in rows[kind] and "library" in rows[kind], kind
    reasons = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(reasons) == len(entries)
    for kind, line in zip(sorted(entries), reasons, strict=True):
        assert line.startswith(f"broken: skill {kind!r}"), line


def test_an_unknown_skill_is_reported_beside_the_real_entries(tmp_path, monkeypatch):
    """`skills show reachr` used to say "(known: none)" beside six shipped skills."""
    monkeypatch.setenv("HRLP_SKILLS", str(tmp_path / "user"))
    shutil.copytree(shipped_library_root() / "reacher", tmp_path / "lib" / "mine")
    runner = CliRunner()
    r = runner.invoke(app, ["skills", "show", "reachr"])
    assert r.exit_code == 2 and r.output.startswith("error: no skill 'reachr'"), r.output
    assert f"(known: {', '.join(SHIPPED)})" in r.output
    r = runner.invoke(app, ["skills", "show", "reachr", "--library", str(tmp_path / "lib")])
    assert r.exit_code == 2 and f"(known: {', '.join(sorted([*SHIPPED, 'mine']))})" in r.output, r.output
    with pytest.raises(ValueError, match=rf"known: {', '.join(sorted([*SHIPPED, 'mine']))}\)"):
        load_skill("reachr", tmp_path / "lib")


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("tiny") / "run"
    list(train(TrainConfig(task="Reacher", steps=16, batch_steps=16, num_envs=4, episode_steps=20), run))
    return run


def _edit_meta(run, edit) -> None:
    path = run / "checkpoint" / META_FILE
    document = json.loads(path.read_text())
    edit(document["meta"])
    path.write_text(json.dumps(document))


def test_a_checkpoints_meta_is_checked_key_by_key_and_its_hash_covers_the_weights(tiny_run, tmp_path):
    """meta.json is not covered by the content hash (the sha256 of the weights, a skill's identity): a checkpoint
    without 'config' used to give `KeyError: 'config'`. Every reader now checks the keys it needs, in one line."""
    runner = CliRunner()
    cases = [
        (lambda m: m.pop("config"), r"no 'config' in its meta \(needed: config, iteration, env_steps, normalizer"),
        (lambda m: m.update(config="Reacher"), r"'config' must be dict, got str 'Reacher'"),
        (lambda m: m.update(iteration=1.5), r"'iteration' must be int, got float 1\.5"),
        (lambda m: m["config"].pop("hidden"), r"its 'config' has no 'hidden'"),
        (lambda m: m["config"].update(trpo=[]), r"its 'config' is malformed"),
    ]
    for i, (edit, problem) in enumerate(cases):
        run = tmp_path / f"run{i}"
        shutil.copytree(tiny_run, run)
        _edit_meta(run, edit)
        with pytest.raises(CheckpointError, match=rf"{run / 'checkpoint' / META_FILE}: {problem}"):
            load_policy(run / "checkpoint")
        with pytest.raises(CheckpointError, match=problem):
            list(train(TrainConfig(task="Reacher", steps=32, batch_steps=16, num_envs=4, episode_steps=20), run, resume=True))
        r = runner.invoke(app, ["eval", str(run), "--episodes", "1"])
        assert r.exit_code == 2, r.output
        lines = [line for line in r.output.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: ") and META_FILE in lines[0], r.output
        with pytest.raises(CheckpointError, match=problem):
            add_run(SkillLibrary(tmp_path / "lib"), run, f"s{i}")
    run = tmp_path / "flipped"  # the weights are what the hash covers: one flipped byte is caught
    shutil.copytree(tiny_run, run)
    data = bytearray((run / "checkpoint" / WEIGHTS_FILE).read_bytes())
    data[-3] ^= 0x01
    (run / "checkpoint" / WEIGHTS_FILE).write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="does not match"):
        load_policy(run / "checkpoint")


def test_a_checkpoint_file_is_read_only_if_it_is_a_regular_file_within_bounds(tmp_path):
    ckpt = save_checkpoint(tmp_path / "ckpt", {"w": torch.zeros(3)}, {"iteration": 1})
    (ckpt / WEIGHTS_FILE).rename(tmp_path / "w")
    (ckpt / WEIGHTS_FILE).symlink_to(tmp_path / "w")
    with pytest.raises(CheckpointError, match=r"weights\.safetensors: a symbolic link .*must be regular files"):
        load_checkpoint(ckpt)
    (ckpt / WEIGHTS_FILE).unlink()
    (tmp_path / "w").rename(ckpt / WEIGHTS_FILE)
    assert load_checkpoint(ckpt)[1] == {"iteration": 1}
    with pytest.raises(CheckpointError, match=r"meta\.json: [0-9,]+ bytes, more than the 10 a checkpoint may hold here"):
        load_checkpoint(ckpt, limits=ReadLimits(max_meta_bytes=10))
    with pytest.raises(CheckpointError, match=r"meta\.json: JSON nested 2 levels deep, more than the 1 allowed"):
        load_checkpoint(ckpt, limits=ReadLimits(max_json_depth=1))
