"""The generic hierarchy on an environment outside hrlp (``goal_envs:PointGoal-v0``, a Dict observation): named parts,
parameter boxes, one decision against stepping the environment by hand, early ends, initiation fall-backs, the three
skill sources (a Python object, a run hrlp trained, a Stable-Baselines3 file) composed under one Manager that learns,
and one line for every bad skill reference before any compute."""

from __future__ import annotations

import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from typer.testing import CliRunner

import goal_envs
from hrlp.cli import app
from hrlp.config import MacroSpec, MicroAction, SACConfig, TrainConfig
from hrlp.evaluate import evaluate_run
from hrlp.skills import DirectControl, Holding, ObsLayout, ObsView, ParamBox, ScriptedSkill
from hrlp.skills.core import Hierarchy, Seeing, decide, initiated, register_observation_parts
from hrlp.skills.library import SkillLibrary
from hrlp.skills.macro_env import MacroEnv
from hrlp.train import env_factory, train, train_with_progress
from hrlp.training import from_run
from hrlp.training.sources import resolve_skill

TASK = "goal_envs:PointGoal-v0"


def test_a_dict_layout_names_its_keys_in_flatten_order_and_a_view_reads_them():
    space = gym.make(TASK).observation_space
    layout = ObsLayout.of_space(space)
    assert layout.parts == (("achieved_goal", 0, 2), ("desired_goal", 2, 4), ("observation", 4, 8)) and layout.dim == 8
    obs = space.sample()
    row = gym.spaces.flatten(space, obs)[None]
    view = ObsView(row, layout, np.array([0]))
    np.testing.assert_array_equal(view["desired_goal"][0], obs["desired_goal"])
    with pytest.raises(KeyError, match="no observation part 'hand'"):
        view["hand"]


def test_a_box_layout_takes_the_parts_a_domain_names_or_one_whole_part():
    box = gym.spaces.Box(-1, 1, (5,))
    assert ObsLayout.of_space(box).parts == (("observation", 0, 5),)
    assert ObsLayout.of_space(box, {"a": slice(0, 2), "all": slice(0, 5)}).parts == (("a", 0, 2), ("all", 0, 5))
    with pytest.raises(ValueError, match="outside a row of 5"):
        ObsLayout((("a", 3, 7),), 5)
    with pytest.raises(ValueError, match="neither a Box nor a Dict"):
        ObsLayout.of_space(gym.spaces.Discrete(3))


def test_a_parameter_box_maps_minus_one_one_onto_its_bounds_and_back():
    box = ParamBox.of([0.0, -2.0], [1.0, 2.0])
    np.testing.assert_allclose(box.to_user(np.array([[-1.0, 1.0], [0.0, 0.0], [3.0, -3.0]])),
                               [[0.0, 2.0], [0.5, 0.0], [1.0, -2.0]])  # fmt: skip
    np.testing.assert_allclose(box.to_unit(np.array([0.25, 1.0])), [-0.5, 0.5])
    for low, high, why in (([1.0], [0.0], "exceeds"), ([0.0], [np.inf], "finite"), ([0.0, 1.0], [1.0], "as many")):
        with pytest.raises(ValueError, match=why):
            ParamBox(tuple(low), tuple(high))


def test_one_decision_of_direct_control_is_the_environment_stepped_with_the_same_actions():
    macro = MacroEnv(gym.make(TASK), [], micro=MicroAction(duration=3), gamma=0.9)
    twin = gym.make(TASK)
    obs, _ = macro.reset(seed=4)
    twin_obs, _ = twin.reset(seed=4)
    np.testing.assert_array_equal(obs, gym.spaces.flatten(twin.observation_space, twin_obs))
    action = np.array([0.5, -1.0])
    obs, reward, *_, info = macro.step((0, action))
    want, gamma = 0.0, 1.0
    for _ in range(3):
        twin_obs, r, *_ = twin.step(action)
        want, gamma = want + gamma * r, gamma * 0.9
    np.testing.assert_allclose(obs, gym.spaces.flatten(twin.observation_space, twin_obs))
    assert reward == pytest.approx(want) and info["tau"] == 3 and info["discount"] == pytest.approx(0.9**3)


def test_a_skill_that_says_it_is_done_ends_its_macro_action_early_and_reports_it():
    macro = MacroEnv(gym.make(TASK), [goal_envs.reach], gamma=1.0)
    obs, _ = macro.reset(seed=0)
    here = obs[macro.layout.span("achieved_goal")]
    _, _, _, _, info = macro.step((0, macro.block(0, here + 0.01)))  # 1 cm away: done after one step
    assert info["tau"] == 1 and info["skill_done"]
    _, _, term, _, info = macro.step((0, macro.block(0, -np.sign(here))))  # over 1 away each way: out of reach in 10
    assert (info["tau"] == 10 or term) and not info["skill_done"]


def test_a_scripted_skill_keeps_per_world_state_from_its_entry_hook():
    starts: dict[int, np.ndarray] = {}

    def begin(obs: ObsView, params: np.ndarray) -> None:
        starts.update({int(i): row.copy() for i, row in zip(obs.idx, obs["achieved_goal"], strict=True)})

    def moved(obs: ObsView, params: np.ndarray) -> np.ndarray:
        return np.array(
            [np.linalg.norm(r - starts[int(i)]) >= 0.15 for i, r in zip(obs.idx, obs["achieved_goal"], strict=True)]
        )

    skill = ScriptedSkill("move", ParamBox.of([-1, -1], [1, 1]), lambda o, p: p, reads=("achieved_goal",), k=10,
                          begin=begin, done=moved)  # fmt: skip
    macro = MacroEnv(gym.make(TASK), [skill], gamma=1.0)
    obs, _ = macro.reset(seed=3)
    towards_centre = -np.sign(obs[macro.layout.span("achieved_goal")][:1])
    _, _, term, _, info = macro.step((0, np.array([towards_centre[0], 0.0])))  # 10 cm a step: 15 cm after the second
    assert (info["tau"] == 2 and info["skill_done"]) or term, info
    assert list(starts) == [0]


def test_parameters_in_a_frame_are_offsets_from_the_named_part_at_the_decision_start():
    macro = MacroEnv(gym.make(TASK), [goal_envs.near_goal])
    obs, _ = macro.reset(seed=2)
    goal = obs[macro.layout.span("desired_goal")]
    np.testing.assert_allclose(macro.parameters(0, np.array([1.0, -1.0])), goal + np.array([0.05, -0.05]))
    macro.step((0, np.zeros(2)))
    macro.step((0, np.zeros(2)))
    got = macro._obs[macro.layout.span("achieved_goal")]
    assert np.linalg.norm(got - goal) < 0.05


def test_initiation_falls_back_to_the_nearest_available_skill_before_the_choice():
    layout = ObsLayout((("x", 0, 1),), 1)
    box = ParamBox((), ())

    def skill(name: str, where: float | None) -> ScriptedSkill:
        return ScriptedSkill(name, box, lambda o, p: np.zeros((len(o), 1)),
                             initiable=None if where is None else (lambda o, w=where: o["x"][:, 0] < w))  # fmt: skip

    skills = [skill("a", None), skill("b", 0.5), skill("c", 0.0), DirectControl(gym.spaces.Box(-1, 1, (1,)))]
    x = np.array([[-1.0], [0.2], [0.7]])
    view = ObsView(x, layout, np.arange(3))
    assert initiated(skills, view, np.full(3, 2)).tolist() == [2, 1, 0]  # c where x < 0, else b where x < 0.5, else a
    assert initiated(skills, view, np.full(3, 3)).tolist() == [3, 3, 3]  # direct control always runs
    assert initiated(skills, view, np.full(3, 2), ran=np.array([-1, 2, 2])).tolist() == [2, 2, 2]  # a running skill goes on


def test_decide_refuses_a_skill_whose_actions_do_not_fit_the_environment():
    layout = ObsLayout((("x", 0, 1),), 1)
    bad = ScriptedSkill("bad", ParamBox((), ()), lambda o, p: np.zeros((len(o), 3)))
    h = Hierarchy((bad,), np.array([2]), layout, 1.0, 2)
    with pytest.raises(ValueError, match=r"skill bad returned actions of shape \(1, 3\), expected \(1, 2\)"):
        decide(h, np.zeros((1, 1)), np.zeros((1, 1)), lambda i, a: (np.zeros((len(i), 1)),) + (np.zeros(len(i)),) * 3)


@pytest.mark.parametrize(
    ("ref", "message"),
    [
        ("no_such_module_x:reach", "cannot import module 'no_such_module_x'"),
        ("goal_envs:nothing", "module 'goal_envs' has no attribute 'nothing'"),
        ("goal_envs:DT", "is a float, not an hrlp.skills.Skill"),
        (":reach", "write a Python skill as MODULE:NAME"),
        ("no-such-skill", "no skill 'no-such-skill'"),
    ],
)
def test_a_bad_skill_reference_is_one_line_naming_it(ref, message):
    with pytest.raises(ValueError, match=message) as e:
        resolve_skill(ref)
    assert "\n" not in str(e.value)


def test_skills_that_do_not_fit_the_environment_are_refused_in_one_line_before_any_compute():
    lacks = ScriptedSkill("lacks", ParamBox((), ()), lambda o, p: o["hand"], reads=("hand",))
    with pytest.raises(ValueError, match=r"skill lacks reads the observation part\(s\) hand, which this environment lacks"):
        MacroEnv(gym.make(TASK), [lacks])
    with pytest.raises(ValueError, match="cannot import module 'no_such_module_x'"):  # at once, before any environment
        env_factory(TASK, macro=MacroSpec(("goal_envs:reach", "no_such_module_x:reach")))
    arm = env_factory("Gripper", macro=MacroSpec(("goal_envs:reach",)))  # the plane's skill on the arm
    with pytest.raises(ValueError, match=r"skill reach reads the observation part\(s\) achieved_goal"):
        arm()


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    """A directory with a flat run hrlp trained on PointGoal (``flat``) and a Stable-Baselines3 PPO file
    (``ppo_point.zip``), both briefly trained: the Manager must learn which skill and parameters to use."""
    sb3 = pytest.importorskip("stable_baselines3")
    root = tmp_path_factory.mktemp("sources")
    model = sb3.PPO("MultiInputPolicy", gym.make(TASK), n_steps=64, batch_size=64, n_epochs=1, seed=0,
                    policy_kwargs={"net_arch": [16]}, device="cpu")  # fmt: skip
    model.learn(128)
    model.save(root / "ppo_point.zip")
    cfg = TrainConfig(task=TASK, steps=2_000, batch_steps=500, num_envs=4, seed=0, hidden=(16,))
    train_with_progress(cfg, root / "flat")
    return root


def test_a_run_on_a_dict_environment_becomes_a_library_skill_that_acts_as_the_run(trained, tmp_path):
    lib = tmp_path / "lib"
    r = CliRunner().invoke(app, ["skills", "add", str(trained / "flat"), "--name", "point", "--library", str(lib),
                                 "--low", "-1", "--high", "1", "--k", "7", "--done-part", "achieved_goal",
                                 "--done-within", "0.05"])  # fmt: skip
    assert r.exit_code == 0, r.output
    skill = resolve_skill("point", lib)
    direct = from_run(trained / "flat", "point", low=-1, high=1, k=7)
    assert skill.parts == direct.parts and skill.param_part == "desired_goal" and skill.k == 7
    assert skill.params == ParamBox.of([-1, -1], [1, 1]) and isinstance(skill.content_hash, str)
    env = gym.make(TASK)
    layout = ObsLayout.of_space(env.observation_space)
    rows = np.stack([gym.spaces.flatten(env.observation_space, env.observation_space.sample()) for _ in range(5)])
    view, params = ObsView(rows, layout, np.arange(5)), np.random.default_rng(0).uniform(-1, 1, (5, 2))
    np.testing.assert_allclose(skill.act(view, params), direct.act(view, params), atol=1e-5)  # float64 and float32 nets
    near = view["achieved_goal"] + 0.01
    assert skill.done(view, near).all() and direct.done(view, near) is None
    listed = CliRunner().invoke(app, ["skills", "list", "--library", str(lib)], env={"COLUMNS": "250"})
    assert listed.exit_code == 0 and "\npoint " in listed.output and "PointGoal-v0" in listed.output, listed.output


def test_a_sac_run_becomes_a_library_skill_that_acts_as_the_run(tmp_path):
    sac = SACConfig(batch_size=16, learning_starts=20, hidden=(16,))
    list(train(TrainConfig(task=TASK, algo="sac", sac=sac, steps=80, batch_steps=40, num_envs=2, seed=0), tmp_path / "sac"))
    lib = tmp_path / "lib"
    r = CliRunner().invoke(app, ["skills", "add", str(tmp_path / "sac"), "--name", "sac_point", "--library", str(lib)])
    assert r.exit_code == 0, r.output
    skill, direct = resolve_skill("sac_point", lib), from_run(tmp_path / "sac", "sac_point")
    assert SkillLibrary(lib).manifest("sac_point")["actor"] == "squashed"
    env = gym.make(TASK)
    layout = ObsLayout.of_space(env.observation_space)
    rows = np.stack([gym.spaces.flatten(env.observation_space, env.observation_space.sample()) for _ in range(5)])
    view, params = ObsView(rows, layout, np.arange(5)), np.random.default_rng(0).uniform(-1, 1, (5, 2))
    np.testing.assert_allclose(skill.act(view, params), direct.act(view, params), atol=1e-5)


def test_a_learned_skill_that_does_not_fit_the_environment_is_refused_in_one_line(trained):
    skill = from_run(trained / "flat", "point", low=-1, high=1)

    class Wider(goal_envs.PointGoal):  # the same parts, a 3-d action
        def __init__(self) -> None:
            super().__init__()
            self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float64)

    with pytest.raises(ValueError, match="skill point emits 2 action numbers; this environment takes 3"):
        MacroEnv(Wider(), [skill])

    class Longer(goal_envs.PointGoal):  # a 6-number state where the skill read 4
        def __init__(self) -> None:
            super().__init__()
            self.observation_space = gym.spaces.Dict({**self.observation_space.spaces,
                                                      "observation": gym.spaces.Box(-np.inf, np.inf, (6,))})  # fmt: skip

    with pytest.raises(ValueError, match="skill point reads 4 numbers of part 'observation'; this environment has 6"):
        MacroEnv(Longer(), [skill])


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("parts", [["achieved_goal", 2], ["desired_goal", 2]], "observation size, the widths of its parts"),
        ("param_part", "hand", "'param_part' 'hand' is not one of its parts"),
        ("action_low", [0.0], "'action_low' must be 2 finite numbers"),
        ("done", {"part": "achieved_goal", "within": -1}, "manifest's 'done' must be"),
        ("param", {"low": [0, 0, 0], "high": [1, 1, 1]}, "parameter box has 3 numbers, its parameter part 2"),
    ],
)
def test_a_tampered_policy_skill_manifest_is_refused_in_one_line(trained, tmp_path, field, value, message):
    import json

    lib = tmp_path / "lib"
    r = CliRunner().invoke(app, ["skills", "add", str(trained / "flat"), "--name", "point", "--library", str(lib),
                                 "--low", "-1", "--high", "1"])  # fmt: skip
    assert r.exit_code == 0, r.output
    meta = lib / "point" / "meta.json"
    document = json.loads(meta.read_text())
    document["meta"][field] = value  # the manifest (the file also holds the weights' sha256 and tensor names)
    meta.write_text(json.dumps(document))
    with pytest.raises(ValueError, match=message) as e:
        resolve_skill("point", lib)
    assert "\n" not in str(e.value) and "skill 'point'" in str(e.value)


class NamedPoint(goal_envs.PointGoal):
    """PointGoal under another id, whose ``observation`` a domain names the parts of: ``pos`` and ``vel``."""


gym.register("NamedPoint-v0", entry_point=NamedPoint, max_episode_steps=40)
register_observation_parts("NamedPoint-v0", {"pos": ("observation", 0, 2), "vel": ("observation", 2, 4)})


def test_a_dict_layout_takes_parts_a_domain_names_inside_its_keys_and_refuses_bad_ones_in_one_line():
    space = gym.make(TASK).observation_space  # achieved_goal, desired_goal, observation: 2 + 2 + 4 numbers
    layout = ObsLayout.of_space(space, {"vel": ("observation", 2, 4)})
    assert layout.span("vel") == slice(6, 8) and layout.span("observation") == slice(4, 8) and layout.dim == 8
    for bad, message in (({"v": ("nothing", 0, 1)}, "must be \\(key, start, stop\\) inside one of the keys"),
                         ({"v": ("observation", 2, 5)}, "spans \\[2, 5\\) of 'observation', which has 4 numbers"),
                         ({"v": slice(0, 2)}, "must be \\(key, start, stop\\)")):  # fmt: skip
        with pytest.raises(ValueError, match=message):
            ObsLayout.of_space(space, bad)
    env = gym.make("NamedPoint-v0")  # the parts a domain declared for the id, found from the environment
    assert ObsLayout.of_env(env).span("pos") == slice(4, 6) and "pos" in MacroEnv(env, [goal_envs.reach]).layout.names
    assert "pos" not in ObsLayout.of_env(gym.make(TASK)).names


def test_a_learned_skill_reads_its_parts_under_the_names_they_have_where_it_runs(trained, tmp_path):
    env = gym.make("NamedPoint-v0")
    layout = ObsLayout.of_env(env)
    rows = np.stack([gym.spaces.flatten(env.observation_space, env.observation_space.sample()) for _ in range(5)])
    view, params = ObsView(rows, layout, np.arange(5)), np.random.default_rng(1).uniform(-1, 1, (5, 2))
    rows[:, layout.span("achieved_goal")] = rows[:, layout.span("pos")]  # a consistent state: achieved_goal is pos
    plain = from_run(trained / "flat", "point", low=-1, high=1)
    moved = rows.copy()  # the same state with achieved_goal scrambled: a bound skill reads the position from pos
    moved[:, layout.span("achieved_goal")] = 5.0
    moved_view = ObsView(moved, layout, np.arange(5))
    bound = from_run(
        trained / "flat", "point", low=-1, high=1, bind={"achieved_goal": ("pos",), "observation": ("pos", "vel")}
    )
    assert set(bound.reads) == {"pos", "vel"}
    np.testing.assert_allclose(bound.act(moved_view, params), plain.act(view, params), atol=1e-12)
    lib = tmp_path / "lib"  # the binding travels in the skill's file
    r = CliRunner().invoke(app, ["skills", "add", str(trained / "flat"), "--name", "bound", "--library", str(lib), "--low",
                                 "-1", "--high", "1", "--bind", "achieved_goal=pos", "--bind",
                                 "observation=pos,vel"])  # fmt: skip
    assert r.exit_code == 0, r.output
    loaded = resolve_skill("bound", lib)
    assert loaded.bind == {"achieved_goal": ("pos",), "observation": ("pos", "vel")}
    np.testing.assert_allclose(loaded.act(moved_view, params), plain.act(view, params), atol=1e-5)
    wide = r"reads 2 numbers of part 'achieved_goal' \(bound to vel\+pos\); this environment has 4"
    for bind, message in (({"achieved_goal": ("vel", "pos")}, wide),
                          ({"achieved_goal": ("speed",)}, r"reads the observation part\(s\) speed")):  # fmt: skip
        with pytest.raises(ValueError, match=message):
            MacroEnv(env, [from_run(trained / "flat", "point", low=-1, high=1, bind=bind)])
    with pytest.raises(ValueError, match="bind names 'desired_goal', which is not one of the parts it reads"):
        from_run(trained / "flat", "point", low=-1, high=1, bind={"desired_goal": ("pos",)})
    r = CliRunner().invoke(app, ["skills", "add", str(trained / "flat"), "--name", "b2", "--library", str(lib), "--low", "-1",
                                 "--high", "1", "--bind", "achieved_goal"])  # fmt: skip
    assert r.exit_code != 0 and "write OWN_PART=PART[,PART...]" in r.output


def test_a_held_action_entry_and_a_part_shown_as_a_constant_wrap_any_skill():
    env = gym.make(TASK)
    layout = ObsLayout.of_space(env.observation_space)
    rows = np.stack([gym.spaces.flatten(env.observation_space, env.observation_space.sample()) for _ in range(4)])
    view, goal = ObsView(rows, layout, np.arange(4)), np.zeros((4, 2))
    held = Holding(goal_envs.reach, {1: 0.5}, "reach_x")
    out, inner = held.act(view, goal), goal_envs.reach.act(view, goal)
    np.testing.assert_array_equal(out[:, 0], inner[:, 0])
    assert (out[:, 1] == 0.5).all() and held.name == "reach_x" and held.params == goal_envs.reach.params
    with pytest.raises(ValueError, match=r"holds action entries \[2\]; this environment's action has 2 numbers"):
        MacroEnv(env, [Holding(goal_envs.reach, {2: 1.0})])
    blind = Seeing(goal_envs.reach, {"achieved_goal": [0.25, -0.5]})  # it sees itself at (0.25, -0.5) wherever it is
    np.testing.assert_allclose(blind.act(view, goal), np.clip(8.0 * (goal - [0.25, -0.5]), -1, 1))
    with pytest.raises(ValueError, match="is shown 3 numbers as part 'achieved_goal', which has 2"):
        MacroEnv(env, [Seeing(goal_envs.reach, {"achieved_goal": [0, 0, 0]})])


def test_skills_add_refuses_bad_parameter_settings_in_one_line(trained, tmp_path):
    for extra, message in ((["--param", "hand"], "no observation part 'hand'"),
                           (["--low", "-1,0,1", "--high", "1"], "low must be one number or 2"),
                           (["--low", "x"], "--low must be numbers separated by commas"),
                           (["--param", "observation"], "has no finite bounds on record")):  # fmt: skip
        r = CliRunner().invoke(app, ["skills", "add", str(trained / "flat"), "--name", "p", "--library",
                                     str(tmp_path / "lib"), *extra])  # fmt: skip
        assert r.exit_code != 0 and message in r.output, (extra, r.output)


def test_a_manager_composes_all_three_skill_sources_on_a_dict_environment_and_learns(trained, tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "my_skills.py").write_text(
        textwrap.dedent(f"""
        from hrlp.skills import from_sb3
        from hrlp.training import from_run

        def sb3_reach():
            return from_sb3({str(trained / "ppo_point.zip")!r}, "sb3_reach", low=-1, high=1, k=10)

        def hrlp_reach():
            return from_run({str(trained / "flat")!r}, "hrlp_reach", k=10, done_part="achieved_goal", done_within=0.05)
    """)
    )
    refs = ("goal_envs:wander", "my_skills:sb3_reach", "my_skills:hrlp_reach", "goal_envs:near_goal")
    macro = env_factory(TASK, macro=MacroSpec(refs))()
    assert macro.names == ["wander", "sb3_reach", "hrlp_reach", "near_goal"] and macro.param_dims == (2, 2, 2, 2)
    cfg = TrainConfig(task=TASK, steps=30_000, batch_steps=500, num_envs=8, seed=0, macro=MacroSpec(refs))
    train_with_progress(cfg, tmp_path / "manager")
    ev = evaluate_run(tmp_path / "manager", episodes=100)
    assert ev.success is not None and ev.success.mean >= 0.9, ev
    assert ev.macro_usage is not None and set(ev.macro_usage) == set(macro.names)
