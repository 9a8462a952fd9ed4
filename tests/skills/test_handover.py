"""Skills that hand over: capsule-relative goals, the approach from above, the open claw, parameters declared in code."""

import json
from dataclasses import replace

import numpy as np
import pytest

from hrlp.arm import make
from hrlp.arm.handover import arm_macro_env
from hrlp.arm.skill import HANDOVER_POINT, HANDOVER_TARGET, PARAM_SPECS, ParamSpec
from hrlp.checkpoint import CheckpointError
from hrlp.config import Handover, MacroSpec, MicroAction
from hrlp.skills import SkillLibrary, load_skill
from hrlp.skills.macro_env import MacroEnv, step_macros

H, C = slice(18, 21), slice(21, 24)


@pytest.fixture(scope="module")
def shipped():
    return [load_skill("gripper"), load_skill("reacher")]


def _twin(seed: int):
    env = make("ReachAndGrip2", episode_steps=60)
    obs, _ = env.reset(seed=seed)
    return env, obs


def test_relative_goals_are_offsets_from_the_capsule_at_the_macro_start(shipped):
    macro = arm_macro_env(make("ReachAndGrip2", episode_steps=60), shipped, k=6,
                     handover=Handover(approach_height=0.0, open_torque=0.0))  # fmt: skip
    obs, _ = macro.reset(seed=4)
    assert macro.param_boxes[1] == HANDOVER_POINT.box() and macro.param_boxes[0] == shipped[0].param.box()
    offset = np.array([0.02, -0.01, 0.05])
    block = (offset - (np.array(HANDOVER_POINT.low) + HANDOVER_POINT.high) / 2) / (
        (np.array(HANDOVER_POINT.high) - HANDOVER_POINT.low) / 2
    )
    goal = obs[C] + offset
    assert macro.parameters(1, block) == pytest.approx(goal) and macro.block(1, goal) == pytest.approx(block)
    macro.step((1, np.zeros(0), block))
    low, low_obs = _twin(4)
    for _ in range(6):  # the capsule moves under the Reacher, the goal stays where it was at the macro's start
        low_obs, *_ = low.step(shipped[1].torques(low_obs[None, :24], goal[None])[0])
    np.testing.assert_allclose(macro.env.physics.hand, low.physics.hand)


def test_the_goal_is_raised_until_the_hand_is_above_it_and_the_claw_is_held_open(shipped):
    h = Handover(relative=False, approach_height=0.11, approach_radius=0.02, open_torque=0.3)
    macro = arm_macro_env(make("ReachAndGrip2", episode_steps=60), shipped, k=5, handover=h)
    obs, _ = macro.reset(seed=1)
    far = obs[C] + (0.0, 0.0, 0.03)  # the hand starts on the palm circle, far from above the capsule
    assert np.linalg.norm(obs[H][:2] - far[:2]) > 0.02
    macro.step((1, np.zeros(0), macro.block(1, far)))
    low, low_obs = _twin(1)
    for _ in range(5):
        a = shipped[1].torques(low_obs[None, :24], np.add(far, (0.0, 0.0, 0.11))[None])[0]
        a[7:] = (-0.3, 0.3)
        low_obs, *_ = low.step(a)
    np.testing.assert_allclose(macro.env.physics.hand, low.physics.hand)
    # Right above the goal the goal is not raised.
    obs = macro._obs
    above = np.concatenate([obs[H][:2], [obs[H][2] - 0.04]])
    macro.step((1, np.zeros(0), macro.block(1, above)))
    for _ in range(5):
        a = shipped[1].torques(low_obs[None, :24], above[None])[0]
        a[7:] = (-0.3, 0.3)
        low_obs, *_ = low.step(a)
    np.testing.assert_allclose(macro.env.physics.hand, low.physics.hand)


def test_handover_leaves_other_macro_actions_alone(shipped):
    h = Handover()
    a = arm_macro_env(make("ReachAndGrip1", episode_steps=40), shipped, k=5, micro=MicroAction(), handover=h)
    b = MacroEnv(make("ReachAndGrip1", episode_steps=40), shipped, k=5, micro=MicroAction())
    for env in (a, b):
        env.reset(seed=2)
        env.step((0, np.zeros(0), np.zeros(3), np.zeros(9)))  # the Gripper
        env.step((2, np.zeros(0), np.zeros(3), np.full(9, 0.3)))  # the micro-action
    np.testing.assert_array_equal(a.env.physics.hand, b.env.physics.hand)


def _scripted_success(skills, handover, episodes=48, reach_calls=8):
    """Reach for 4 cm above the capsule for ``reach_calls`` macro-actions, then grip: the plan a Manager has to find."""
    envs = [arm_macro_env(make("ReachAndGrip1"), skills, k=10, handover=handover) for _ in range(episodes)]
    for i, e in enumerate(envs):
        e.reset(seed=i)
    success, done = np.zeros(episodes, dtype=bool), np.zeros(episodes, dtype=bool)
    for t in range(30):
        rows = [np.concatenate([[1 if t < reach_calls else 0], e.block(1, e._obs[C] + (0, 0, 0.04))]) for e in envs]
        res = step_macros(envs, np.clip(np.array(rows), -1, 1))
        success |= ~done & np.array([bool(i.get("success")) for i in res.infos])
        done |= res.terminated | res.truncated
    return success.mean()


def test_mover_targets_relative_to_the_tasks_target_reach_the_mover_as_that_point():
    skills = [load_skill("reacher-handover"), load_skill("gripper-imitated"), load_skill("mover-held")]
    handover = Handover(approach_height=0.0, open_torque=0.0, target_relative=True)
    macro = arm_macro_env(make("ReachAndMove", episode_steps=45), skills, k=15, handover=handover)
    obs, _ = macro.reset(seed=2)
    assert macro.param_boxes[2] == HANDOVER_TARGET.box() and macro.param_boxes[0] == HANDOVER_POINT.box()
    assert macro.param_boxes[1] == skills[1].param.box()  # the Gripper has no parameters
    offset = np.array([0.05, -0.02, 0.1])  # the box's corner in z: block +1
    block = offset / 0.1
    assert macro.parameters(2, block) == pytest.approx(obs[24:27] + offset)
    assert macro.block(2, obs[24:27] + offset) == pytest.approx(block)
    # The Mover is given T + offset: the same torques as the skill fed that point directly.
    low = make("ReachAndMove", episode_steps=45)
    low_obs, _ = low.reset(seed=2)
    macro.step((2, np.zeros(3), np.zeros(0), block))
    for _ in range(15):
        low_obs, *_ = low.step(skills[2].torques(low_obs[None, :24], (obs[24:27] + offset)[None])[0])
    np.testing.assert_allclose(macro.env.physics.qpos, low.physics.qpos)
    # A task without a target has nothing to be relative to: refused when the Manager's environment is made.
    with pytest.raises(ValueError, match="needs a task that observes a target"):
        arm_macro_env(make("ReachAndGrip2"), skills, k=15, handover=handover)
    assert arm_macro_env(make("ReachAndGrip2"), skills, k=15, handover=Handover()).param_boxes[2] == skills[2].param.box()


def test_the_shipped_reacher_hands_over_to_the_gripper_only_through_the_handover_interface(shipped):
    paper, handover = _scripted_success(shipped, None), _scripted_success(shipped, Handover())
    assert paper < 0.25 and handover > 0.6, (paper, handover)


def test_the_shipped_handover_reacher_hands_over_through_the_papers_interface():
    # Trained for hand-over (ReacherHandover), it needs none of the drives: absolute goals, its own finger torques.
    skills = [load_skill("gripper"), load_skill("reacher-handover")]
    assert _scripted_success(skills, None, episodes=24) >= 0.9


def test_parameters_are_declared_in_code_and_manifests_cannot_redefine_them(tmp_path):
    lib = SkillLibrary(tmp_path)
    import shutil

    from hrlp.arm.skill_files import shipped_library_root

    shutil.copytree(shipped_library_root() / "reacher", tmp_path / "r")
    meta_path = tmp_path / "r" / "meta.json"
    raw = json.loads(meta_path.read_text())
    raw["meta"]["param"]["low"], raw["meta"]["param"]["high"] = [-9, -9, -9], [9, 9, 9]  # an edited copy is ignored
    meta_path.write_text(json.dumps(raw))
    assert lib.load("r").param == PARAM_SPECS["Reacher"]
    raw["meta"]["param"].update(dim=2, low=[0, 0], high=[1, 1])
    meta_path.write_text(json.dumps(raw))
    with pytest.raises(CheckpointError, match="do not match task Reacher"):
        lib.load("r")


def test_bad_frames_and_handover_settings_are_refused():
    with pytest.raises(ValueError, match="unknown frame 'table'"):
        ParamSpec(3, (0, 0, 0), (1, 1, 1), "x", frame="table")
    with pytest.raises(ValueError, match="3-d point"):
        ParamSpec(2, (0, 0), (1, 1), "x", frame="capsule")
    for bad in ({"open_torque": 2.0}, {"approach_height": -0.1}, {"approach_radius": True}):
        with pytest.raises(ValueError, match="Handover"):
            Handover(**bad)
    with pytest.raises(ValueError, match=r"Handover\.target_relative must be true or false"):
        Handover(target_relative="yes")
    with pytest.raises(ValueError, match="approach_radius must be positive"):
        Handover(approach_radius=0.0)


def test_macro_spec_round_trips_the_handover_and_reads_configs_without_it():
    spec = MacroSpec(("gripper", "reacher"), k=10, handover=Handover(open_torque=0.1))
    assert MacroSpec.from_json(json.loads(json.dumps(spec.to_json()))) == spec
    carry = MacroSpec(("reacher-handover", "mover-held"), k=15, handover=Handover(target_relative=True))
    assert MacroSpec.from_json(json.loads(json.dumps(carry.to_json()))) == carry
    older = spec.to_json()
    del older["handover"]["target_relative"]  # a hand-over config from before target_relative
    assert MacroSpec.from_json(older).handover == Handover(open_torque=0.1)
    old = {"skills": ["gripper", "reacher"], "k": 10, "micro": None, "library": None}  # a config from before handover
    assert MacroSpec.from_json(old).handover is None


def test_train_manager_handover_flag_is_recorded_and_resume_keeps_it(tmp_path):
    from typer.testing import CliRunner

    from hrlp.cli import app

    run = tmp_path / "m"
    args = ["train-manager", "ReachAndGrip1", "--skills", "gripper,reacher", "--k", "3", "--handover", "--steps", "60",
            "--batch-steps", "12", "--num-envs", "2", "--episode-steps", "12", "--run-dir", str(run)]  # fmt: skip
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    saved = json.loads((run / "config.json").read_text())
    assert MacroSpec.from_json(saved["macro"]).handover == Handover()
    r = CliRunner().invoke(app, ["train-manager", "ReachAndGrip1", "--no-handover", "--steps", "120", "--run-dir", str(run),
                                 "--resume"])  # fmt: skip
    assert r.exit_code == 2 and "--handover False (the run: on)" in r.output, r.output


def test_train_manager_sets_the_handover_drive_and_resume_compares_it(tmp_path):
    from typer.testing import CliRunner

    from hrlp.cli import app

    run = tmp_path / "m"
    args = ["train-manager", "ReachAndGrip1", "--skills", "gripper,reacher", "--k", "3", "--handover-approach-height", "0",
            "--handover-open-torque", "0", "--steps", "24", "--batch-steps", "12", "--num-envs", "2", "--episode-steps",
            "12", "--run-dir", str(run)]  # fmt: skip
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    saved = MacroSpec.from_json(json.loads((run / "config.json").read_text())["macro"])
    assert saved.handover == Handover(approach_height=0.0, open_torque=0.0)  # relative goals only: the skill as trained
    r = CliRunner().invoke(app, ["train-manager", "ReachAndGrip1", "--handover-open-torque", "0.3", "--steps", "48",
                                 "--run-dir", str(run), "--resume"])  # fmt: skip
    assert r.exit_code == 2 and "--handover-open-torque 0.3 (the run: 0.0)" in r.output, r.output
    r = CliRunner().invoke(app, ["train-manager", "ReachAndGrip1", "--skills", "gripper,reacher", "--no-handover",
                                 "--handover-open-torque", "0", "--run-dir", str(tmp_path / "x")])  # fmt: skip
    assert r.exit_code == 2 and "--handover-open-torque sets how Reachers are driven" in r.output, r.output
    r = CliRunner().invoke(app, ["train-manager", "ReachAndGrip1", "--skills", "gripper,reacher", "--handover-open-torque",
                                 "1.5", "--run-dir", str(tmp_path / "y")])  # fmt: skip
    assert r.exit_code == 2 and "--handover-open-torque" in r.output, r.output
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_train_manager_passes_mover_targets_relative_to_the_tasks_target(tmp_path):
    from typer.testing import CliRunner

    from hrlp.cli import app

    run = tmp_path / "m"
    args = ["train-manager", "ReachAndMove", "--skills", "reacher-handover,gripper-imitated,mover-held", "--k", "3",
            "--handover-approach-height", "0", "--handover-open-torque", "0", "--handover-target-relative", "--steps", "24",
            "--batch-steps", "12", "--num-envs", "2", "--episode-steps", "12", "--run-dir", str(run)]  # fmt: skip
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    saved = MacroSpec.from_json(json.loads((run / "config.json").read_text())["macro"])
    assert saved.handover == Handover(approach_height=0.0, open_torque=0.0, target_relative=True)
    r = CliRunner().invoke(app, ["train-manager", "ReachAndMove", "--no-handover-target-relative", "--steps", "48",
                                 "--run-dir", str(run), "--resume"])  # fmt: skip
    assert r.exit_code == 2 and "--handover-target-relative False (the run: True)" in r.output, r.output
    # On a task without a target the Manager's environment refuses it, in one line, before training starts.
    r = CliRunner().invoke(app, ["train-manager", "ReachAndGrip1", "--skills", "gripper,mover-held",
                                 "--handover-target-relative", "--steps", "24", "--run-dir", str(tmp_path / "x")])  # fmt: skip
    assert r.exit_code != 0 and "needs a task that observes a target" in r.output, r.output


def _base(hand, capsule):
    obs = np.zeros((len(hand), 24))
    obs[:, H], obs[:, C] = hand, capsule
    return obs


def test_initiation_sets_hold_where_their_skills_were_trained_to_start():
    from hrlp.arm.physics import CAPSULE_REST_Z
    from hrlp.arm.skill import Initiation

    rest, up = CAPSULE_REST_Z, CAPSULE_REST_Z + 0.02
    capsule = np.array([[0.0, 0.0, rest], [0.0, 0.0, rest], [0.0, 0.0, up], [0.0, 0.0, rest + 0.005]])
    hand = capsule + np.array([[0.0, 0.0, 0.3], [0.0, 0.06, 0.0], [0.0, 0.0, 0.0], [0.08, 0.0, 0.0]])
    obs = _base(hand, capsule)
    np.testing.assert_array_equal(Initiation().holds(obs), [True, True, True, True])
    np.testing.assert_array_equal(Initiation(capsule="resting").holds(obs), [True, True, False, True])  # 5 mm: resting
    np.testing.assert_array_equal(Initiation(capsule="lifted").holds(obs), [False, False, True, False])
    np.testing.assert_array_equal(Initiation(hand_within=0.07).holds(obs), [False, True, True, False])
    assert Initiation(hand_within=0.09).describe() == "the hand within 9 cm of the capsule"
    assert Initiation(capsule="lifted").describe() == "the capsule lifted" and Initiation().describe() == "anywhere"
    for bad in ({"capsule": "held"}, {"hand_within": 0.0}, {"hand_within": True}, {"hand_within": float("nan")}):
        with pytest.raises(ValueError, match="Initiation"):
            Initiation(**bad)


def test_initiation_sets_are_declared_from_the_training_task_and_read_from_shipped_manifests():
    from hrlp.arm.skill import Initiation, initiation_for

    assert initiation_for("ReacherHandover") == Initiation(capsule="resting")
    assert initiation_for("Gripper") == Initiation(hand_within=0.09)
    assert initiation_for("Gripper", {"start_distance": [0.0, 0.05]}) == Initiation(hand_within=0.05)
    assert initiation_for("MoverNoised", {"starts": "held"}) == Initiation(capsule="lifted")
    assert initiation_for("MoverPlain") == Initiation(hand_within=0.09)
    assert initiation_for("ReachAndGrip2") == Initiation()
    with pytest.raises(ValueError, match="start_distance must be two numbers"):
        initiation_for("Gripper", {"start_distance": "far"})
    shipped = {n: load_skill(n).initiation for n in ("reacher-handover", "gripper-imitated", "mover-held", "mover-noised")}
    assert shipped == {"reacher-handover": Initiation(capsule="resting"), "gripper-imitated": Initiation(hand_within=0.09),
                       "mover-held": Initiation(capsule="lifted"), "mover-noised": Initiation(hand_within=0.09)}  # fmt: skip


def test_a_damaged_manifests_task_settings_are_named_when_the_skill_is_read(tmp_path):
    import shutil

    from hrlp.arm.skill_files import shipped_library_root

    shutil.copytree(shipped_library_root() / "gripper-imitated", tmp_path / "g")
    meta_path = tmp_path / "g" / "meta.json"
    raw = json.loads(meta_path.read_text())
    raw["meta"]["trained"]["config"]["task_kwargs"] = {"start_distance": "near"}
    meta_path.write_text(json.dumps(raw))
    with pytest.raises(CheckpointError, match="start_distance must be two numbers"):
        SkillLibrary(tmp_path).load("g")


def _carry_skills():
    return [load_skill("reacher-handover"), load_skill("gripper-imitated"), load_skill("mover-held")]


_INIT = Handover(approach_height=0.0, open_torque=0.0, target_relative=True, initiation=True)
_NEAR = np.array([0.0, 0.0, -0.6])  # the Reacher's block for C + (0, 0, 4 cm)


def test_a_choice_outside_its_set_runs_the_nearest_skill_before_it_whose_set_holds():
    import gymnasium as gym

    from hrlp.arm.physics import BASE_PARTS
    from hrlp.skills.core import ObsLayout, ObsView
    from hrlp.skills.core import initiated as chosen

    def initiated(skills, obs, choice, ran=None):  # the arm's base parts, read by name
        layout = ObsLayout.of_space(gym.spaces.Box(-np.inf, np.inf, (obs.shape[1],)), BASE_PARTS)
        return chosen(skills, ObsView(obs, layout, np.arange(len(obs))), choice, ran)

    skills = _carry_skills()  # resting; the hand within 9 cm; lifted
    c0 = np.array([0.0, 0.0, 0.025])
    far, near, up = (0.0, 0.0, 0.3), (0.0, 0.0, 0.05), (0.0, 0.0, 0.03)
    states = {"far, resting": (c0 + far, c0), "near, resting": (c0 + near, c0), "near, lifted": (c0 + up + near, c0 + up),
              "far, lifted": (c0 + up + far, c0 + up)}  # fmt: skip
    obs = _base(*map(np.array, zip(*states.values(), strict=True)))
    run = {c: initiated(skills, obs, np.full(4, c)).tolist() for c in range(4)}
    assert run[2] == [0, 1, 2, 2]  # the Mover: reach, then grip, then carry (its prerequisites first)
    assert run[1] == [0, 1, 1, 2]  # the Gripper: reach first; lifted out of reach: the one skill whose set holds
    assert run[0] == [0, 0, 1, 2]  # the Reacher while the capsule is lifted: nothing before it, the first that holds
    assert run[3] == [3, 3, 3, 3]  # the micro-action (index len(skills)) always runs
    going_on = initiated(skills, obs, np.full(4, 1), ran=np.array([1, 0, -1, 1]))
    assert going_on.tolist() == [1, 1, 1, 1]  # a Gripper chosen again goes on, wherever it took the arm
    prerequisite = initiated(skills, obs, np.full(4, 2), ran=np.array([1, 1, 0, -1]))
    assert prerequisite.tolist() == [1, 1, 2, 2]  # the Mover chosen while the Gripper is at work: the Gripper goes on


def test_a_skill_chosen_outside_its_initiation_set_runs_another_with_its_own_block():
    skills = _carry_skills()
    free = arm_macro_env(make("ReachAndMove", episode_steps=90), skills, k=15, handover=_INIT)
    plain = arm_macro_env(make("ReachAndMove", episode_steps=90), skills, k=15,
                     handover=Handover(approach_height=0.0, open_torque=0.0, target_relative=True))  # fmt: skip
    obs, _ = free.reset(seed=3)
    plain.reset(seed=3)
    assert obs[23] == pytest.approx(0.025) and np.linalg.norm(obs[H] - obs[C]) > 0.09  # resting, the hand far
    # The Mover (capsule not lifted) and the Gripper (hand beyond 9 cm) chosen here: the Reacher runs, with its block,
    # and the rendered frames are labelled with it.
    assert (free.would_run(2), free.would_run(1), plain.would_run(2)) == (0, 0, 2)
    labels: list[str] = []
    free.on_substep = labels.append
    _, r, *_, info = free.step((2, _NEAR, np.zeros(0), np.zeros(3)))
    assert labels == ["reacher-handover"] * 15
    _, r_plain, *_, info_plain = plain.step((0, _NEAR, np.zeros(0), np.zeros(3)))
    assert info["macro"] == info_plain["macro"] == "reacher-handover" and r == r_plain
    np.testing.assert_array_equal(free.env.physics.qpos, plain.env.physics.qpos)
    _, _, *_, info = free.step((1, _NEAR, np.zeros(0), np.zeros(3)))
    assert info["macro"] == "reacher-handover"


def test_a_chosen_skill_goes_on_where_it_left_the_arm_and_the_mover_starts_once_the_capsule_is_lifted():
    macro = arm_macro_env(make("ReachAndMove", episode_steps=150), _carry_skills(), k=15, handover=_INIT)
    obs, _ = macro.reset(seed=0)
    ran, hand = [], []
    for t in range(10):
        lifted = obs[23] - 0.025 > 0.01
        choice = 0 if t < 3 else (2 if lifted else 1)
        obs, *_, info = macro.step((choice, _NEAR, np.zeros(0), macro.block(2, obs[24:27])))
        ran.append(info["macro"])
        hand.append(float(np.linalg.norm(obs[H] - obs[C])))
    assert ran[:3] == ["reacher-handover"] * 3 and "mover-held" in ran, (ran, hand)
    grips = [i for i, name in enumerate(ran) if name == "gripper-imitated"]
    assert grips and grips == list(range(3, 3 + len(grips))), ran  # the Gripper went on, call after call
    state = macro.get_state()
    assert state["ran"] == macro.names.index(ran[-1])
    macro.reset(seed=1)
    assert macro.get_state()["ran"] == -1
    macro.set_state({k: v for k, v in state.items() if k != "ran"})  # a state saved before "ran": none yet
    assert macro.get_state()["ran"] == -1


@pytest.mark.parametrize("backend", ["loop", "rollout"])
def test_initiation_sets_run_the_same_macro_actions_in_the_batched_worlds(backend):
    from hrlp.arm.batched import make_batched
    from hrlp.arm.manager import batched_manager
    from hrlp.skills.macro_env import manager_vector_env

    n, skills = 4, _carry_skills()
    build = lambda: arm_macro_env(make("ReachAndMove", episode_steps=60), skills, k=15, handover=_INIT)  # noqa: E731
    serial = manager_vector_env([build() for _ in range(n)])
    batched = batched_manager(make_batched("ReachAndMove", n, episode_steps=60, backend=backend), build())
    obs = serial.reset(seed=5)
    np.testing.assert_array_equal(obs, batched.reset(seed=5))
    rng, runs = np.random.default_rng(0), []
    for t in range(8):  # two episodes each: the record of the macro-action run is cleared at the resets
        choice = rng.integers(0, 3, n) if t % 4 < 2 else np.where(obs[:, 23] > 0.035, 2, 1)  # reach, then grip
        actions = np.concatenate([choice[:, None], np.tile(_NEAR, (n, 1)), rng.uniform(-1, 1, (n, 3))], axis=1)
        a, b = serial.step(actions), batched.step(actions)
        obs = a.obs
        np.testing.assert_array_equal(a.infos["choice"], b.infos["choice"])
        np.testing.assert_allclose(b.next_obs, a.next_obs, atol=1e-6)
        runs.append(a.infos["choice"])
    assert len(np.unique(runs)) >= 2
    state = batched.get_state()
    serial.set_state(state)  # the same format: the macro-actions run carry over
    assert serial._ran.tolist() == batched._ran.tolist()


def test_handover_initiation_round_trips_and_older_configs_read_as_off():
    spec = MacroSpec(("reacher-handover", "gripper-imitated", "mover-held"), k=15, handover=_INIT)
    assert MacroSpec.from_json(json.loads(json.dumps(spec.to_json()))) == spec
    older = spec.to_json()
    del older["handover"]["initiation"]
    assert MacroSpec.from_json(older).handover == Handover(approach_height=0.0, open_torque=0.0, target_relative=True)
    with pytest.raises(ValueError, match=r"Handover\.initiation must be true or false"):
        Handover(initiation=1)
    pregrasp = MacroSpec(spec.skills, k=50, handover=replace(_INIT, pregrasp=True))
    assert MacroSpec.from_json(json.loads(json.dumps(pregrasp.to_json()))) == pregrasp
    with pytest.raises(ValueError, match="pregrasp is a box of capsule-relative goals"):
        Handover(relative=False, pregrasp=True)


def test_pregrasp_goals_centre_4_cm_above_the_capsule_within_the_grippers_reach():
    from hrlp.arm.skill import HANDOVER_PREGRASP

    macro = arm_macro_env(
        make("ReachAndMove", episode_steps=150), _carry_skills(), k=15, handover=replace(_INIT, pregrasp=True)
    )
    obs, _ = macro.reset(seed=4)
    assert macro.param_boxes[0] == HANDOVER_PREGRASP.box()
    assert macro.parameters(0, np.zeros(3)) == pytest.approx(obs[C] + (0, 0, 0.04))  # the Manager's first mean goal
    assert macro.parameters(0, np.ones(3)) == pytest.approx(obs[C] + (0.03, 0.03, 0.08))
    for _ in range(3):  # from its first mean goal the Reacher leaves the palm where the Gripper starts
        obs, *_ = macro.step((0, np.zeros(3), np.zeros(0), np.zeros(3)))
    assert np.linalg.norm(obs[H] - obs[C]) < 0.09 and macro.skills[1].initiation.holds(obs[None])[0]


def test_train_manager_sets_initiation_sets_and_resume_compares_them(tmp_path):
    from typer.testing import CliRunner

    from hrlp.cli import app

    run = tmp_path / "m"
    args = ["train-manager", "ReachAndMove", "--skills", "reacher-handover,gripper-imitated,mover-held", "--k", "3",
            "--handover-initiation", "--steps", "24", "--batch-steps", "12", "--num-envs", "2", "--episode-steps", "12",
            "--run-dir", str(run)]  # fmt: skip
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    assert MacroSpec.from_json(json.loads((run / "config.json").read_text())["macro"]).handover == Handover(initiation=True)
    r = CliRunner().invoke(app, ["train-manager", "ReachAndMove", "--no-handover-initiation", "--steps", "48",
                                 "--run-dir", str(run), "--resume"])  # fmt: skip
    assert r.exit_code == 2 and "--handover-initiation False (the run: True)" in r.output, r.output
    r = CliRunner().invoke(app, ["train-manager", "ReachAndMove", "--skills", "reacher-handover,mover-held", "--no-handover",
                                 "--handover-initiation", "--run-dir", str(tmp_path / "x")])  # fmt: skip
    assert r.exit_code == 2 and "--handover-initiation sets how Reachers are driven" in r.output, r.output
