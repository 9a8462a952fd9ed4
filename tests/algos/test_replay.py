"""The replay buffer: ring storage, episode ends, goal relabelling (HER's future strategy, a Manager's discounted span)
and an exact round trip through its saved state."""

import numpy as np
import pytest

from hrlp.algos.replay import GoalSpec, ReplayBuffer

GAMMA = 0.9


def _goals(terminated=None):
    def reward(achieved, desired, info):
        return -(np.linalg.norm(achieved - desired, axis=-1) > 0.05).astype(np.float64)

    # observation layout: [achieved (2), desired (2), step counter (1)]
    return GoalSpec(slice(0, 2), slice(2, 4), reward, terminated)


def _fill(buffer, steps, n, episode=5, tau=1):
    """``steps`` rows of ``n`` environments; environment i's achieved goal after row t is (t, i), its goal (-1, -1);
    episodes end every ``episode`` rows."""
    for t in range(steps):
        obs = np.zeros((n, 5))
        obs[:, 0], obs[:, 1], obs[:, 2:4], obs[:, 4] = t - 1, np.arange(n), -1, t
        nxt = obs.copy()
        nxt[:, 0] = t
        done = np.full(n, (t + 1) % episode == 0)
        buffer.add(obs, nxt, np.full((n, 1), t), np.full(n, -1.0), np.full(n, GAMMA**tau), np.zeros(n, bool), done,
                   np.full(n, tau))  # fmt: skip


def test_a_full_buffer_keeps_the_newest_rows():
    b = ReplayBuffer(10, 2, 5, 1, GAMMA)
    _fill(b, 8, 2)
    assert b.size == 10 and b.rows == 5 and b.written == 8
    steps = {int(s) for s in b.sample(500, np.random.default_rng(0))["obs"][:, 4]}
    assert steps == {3, 4, 5, 6, 7}


def test_episode_ends_are_recorded_for_the_rows_still_held_and_open_while_running():
    b = ReplayBuffer(40, 1, 5, 1, GAMMA)
    _fill(b, 12, 1, episode=5)
    assert b.episode_end[:5, 0].tolist() == [4] * 5 and b.episode_end[5:10, 0].tolist() == [9] * 5
    assert b.episode_end[10:12, 0].tolist() == [-1, -1]


def test_relabelled_goals_are_achieved_later_in_the_same_episode_and_rewarded_by_the_environment():
    b = ReplayBuffer(100, 3, 5, 1, GAMMA, _goals(), her_future=4)
    _fill(b, 20, 3, episode=5)
    s = b.sample(4000, np.random.default_rng(1))
    relabelled = s["obs"][:, 2] != -1
    assert 0.75 < relabelled.mean() < 0.85  # her_future 4: a share of 4/5
    goal, t, env = s["obs"][relabelled, 2:4], s["obs"][relabelled, 4], s["obs"][relabelled, 1]
    assert np.array_equal(goal[:, 1], env)  # the same environment's achieved goal
    episode_end = (t // 5) * 5 + 4
    assert ((goal[:, 0] >= t) & (goal[:, 0] <= episode_end)).all()  # from itself to its episode's end
    assert np.array_equal(s["next_obs"][relabelled, 2:4], goal)
    reached = goal[:, 0] == t  # the goal it achieved itself
    assert (s["rewards"][relabelled][reached] == 0).all() and (s["rewards"][relabelled][~reached] == -1).all()
    assert (s["rewards"][~relabelled] == -1).all()


def test_a_running_episode_is_relabelled_with_what_it_has_achieved_so_far():
    b = ReplayBuffer(100, 1, 5, 1, GAMMA, _goals(), her_future=1000)
    _fill(b, 7, 1, episode=5)  # the second episode is at rows 5 and 6
    s = b.sample(500, np.random.default_rng(2))
    second = (s["obs"][:, 4] >= 5) & (s["obs"][:, 2] != -1)
    assert second.sum() > 100 and set(s["obs"][second, 2].tolist()) == {5.0, 6.0}


def test_a_managers_relabelled_reward_spans_its_discounts_and_termination_comes_from_the_environment():
    ended = _goals(terminated=lambda achieved, desired, info: np.linalg.norm(achieved - desired, axis=-1) <= 0.05)
    b = ReplayBuffer(100, 1, 5, 1, GAMMA, ended, her_future=1000)
    _fill(b, 5, 1, episode=5, tau=3)
    s = b.sample(300, np.random.default_rng(3))
    span = 1 + GAMMA + GAMMA**2
    relabelled = s["obs"][:, 2] != -1
    reached = s["obs"][:, 2] == s["obs"][:, 4]
    assert relabelled.sum() > 250 and reached.any() and (relabelled & ~reached).any()
    assert np.allclose(s["rewards"][reached], 0.0) and np.allclose(s["rewards"][relabelled & ~reached], -span)
    assert np.array_equal(s["terminated"][relabelled], reached[relabelled].astype(np.float32))


def test_without_goals_or_with_her_off_nothing_is_relabelled():
    for b in (ReplayBuffer(50, 1, 5, 1, GAMMA), ReplayBuffer(50, 1, 5, 1, GAMMA, _goals(), her_future=0)):
        _fill(b, 10, 1)
        assert (b.sample(200, np.random.default_rng(0))["obs"][:, 2] == -1).all()


def test_the_saved_state_restores_a_buffer_that_draws_the_same_minibatches():
    a = ReplayBuffer(12, 2, 5, 1, GAMMA, _goals())
    _fill(a, 9, 2, episode=4)
    tensors, meta = a.state()
    b = ReplayBuffer(12, 2, 5, 1, GAMMA, _goals())
    b.load_state(tensors, meta)
    x, y = a.sample(64, np.random.default_rng(5)), b.sample(64, np.random.default_rng(5))
    assert all(np.array_equal(x[k], y[k]) for k in x)
    _fill(a, 3, 2)
    _fill(b, 3, 2)
    x, y = a.sample(64, np.random.default_rng(6)), b.sample(64, np.random.default_rng(6))
    assert all(np.array_equal(x[k], y[k]) for k in x)
    with pytest.raises(ValueError, match="rows"):
        ReplayBuffer(40, 2, 5, 1, GAMMA).load_state(tensors, meta)


def test_memory_is_stated_per_transition_and_a_million_manager_decisions_fit_in_2_gb():
    b = ReplayBuffer(1000, 4, 24, 10, GAMMA)
    assert b.nbytes() == 1000 * (4 * (2 * 24 + 10 + 2) + 11)
    # The arm's Manager with gripper, reacher and the micro-action: 24 observation numbers, actions [k, 3 + 9 parameters].
    assert ReplayBuffer(1_000_000, 4, 24, 13, GAMMA).nbytes() == 263_000_000 < 2 * 2**30


def _fill_paths(buffer, steps, tau=3, k=4, path=True):
    """Like :func:`_fill` with one environment and macro-transitions of ``tau`` low-level steps: within row ``t`` the
    achieved goal moves from ``t - 1`` to ``t`` in ``tau`` equal steps (rows past ``tau`` repeat ``t``)."""
    for t in range(steps):
        obs = np.array([[t - 1, 0, -1, -1, t]], float)
        nxt = obs.copy()
        nxt[0, 0] = t
        inside = np.repeat(nxt[:, None], k, axis=1)
        inside[0, :tau, 0] = t - 1 + np.arange(1, tau + 1) / tau
        buffer.add(obs, nxt, np.full((1, 1), t), np.full(1, -1.0), np.full(1, GAMMA**tau), np.zeros(1, bool),
                   np.array([(t + 1) % 5 == 0]), np.full(1, tau), inside if path else None)  # fmt: skip


def test_a_relabelled_macro_transition_is_scored_at_each_of_its_low_level_steps():
    b = ReplayBuffer(100, 1, 5, 1, GAMMA, _goals(), her_future=1000, path_len=4)
    _fill_paths(b, 5)
    s = b.sample(300, np.random.default_rng(3))
    reached = s["obs"][:, 2] == s["obs"][:, 4]  # its own end: reached only at its third and last step
    later = (s["obs"][:, 2] != -1) & ~reached
    assert reached.sum() > 30 and later.sum() > 30
    assert np.allclose(s["rewards"][reached], -(1 + GAMMA))  # the fourth row repeats the end and is not counted
    assert np.allclose(s["rewards"][later], -(1 + GAMMA + GAMMA**2))
    # Without the steps the end state stands for each of them: the same goal scores as if held throughout.
    end_only = ReplayBuffer(100, 1, 5, 1, GAMMA, _goals(), her_future=1000)
    _fill_paths(end_only, 5, path=False)
    s = end_only.sample(300, np.random.default_rng(3))
    assert np.allclose(s["rewards"][s["obs"][:, 2] == s["obs"][:, 4]], 0.0)


def test_relabelled_rewards_are_scaled_like_the_stored_ones():
    b = ReplayBuffer(100, 1, 5, 1, GAMMA, _goals(), her_future=1000, path_len=4, reward_scale=10.0)
    _fill_paths(b, 5)
    s = b.sample(300, np.random.default_rng(3))
    reached = s["obs"][:, 2] == s["obs"][:, 4]
    assert reached.any() and np.allclose(s["rewards"][reached], -10 * (1 + GAMMA))


def test_a_macro_path_of_the_wrong_shape_is_refused_in_one_line():
    b = ReplayBuffer(100, 1, 5, 1, GAMMA, _goals(), her_future=4, path_len=4)
    with pytest.raises(ValueError, match=r"path has shape \[1, 3, 5\], expected \[1, 4, 5\]"):
        b.add(np.zeros((1, 5)), np.zeros((1, 5)), np.zeros((1, 1)), np.zeros(1), np.ones(1), np.zeros(1, bool),
              np.zeros(1, bool), np.ones(1), np.zeros((1, 3, 5)))  # fmt: skip


def test_paths_survive_the_saved_state_and_a_state_saved_without_them_scores_by_end_states():
    a = ReplayBuffer(100, 1, 5, 1, GAMMA, _goals(), her_future=1000, path_len=4)
    _fill_paths(a, 7)
    tensors, meta = a.state()
    b = ReplayBuffer(100, 1, 5, 1, GAMMA, _goals(), her_future=1000, path_len=4)
    b.load_state(tensors, meta)
    x, y = a.sample(64, np.random.default_rng(5)), b.sample(64, np.random.default_rng(5))
    assert all(np.array_equal(x[k], y[k]) for k in x)
    old = {name: t for name, t in tensors.items() if name != "replay.path"}  # a checkpoint of an earlier version
    c = ReplayBuffer(100, 1, 5, 1, GAMMA, _goals(), her_future=1000, path_len=4)
    c.load_state(old, meta)
    assert np.array_equal(c.path[:7, 0, :, 0], np.repeat(np.arange(7.0)[:, None], 4, axis=1))
