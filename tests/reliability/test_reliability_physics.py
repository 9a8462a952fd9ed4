"""Physics blow-ups are flagged at any step, the first of an episode included, from MuJoCo's own warning counters
(docs/reliability.md, item 2)."""

import logging

import numpy as np
import pytest

from hrlp.arm import make
from hrlp.arm.physics import ArmPhysics

#: Ways to force a blow-up: each trips one of MuJoCo's checks (mj_checkPos, mj_checkVel, mj_checkAcc).
BLOW_UPS = {
    "bad_qpos": lambda d: d.qpos.__setitem__(0, np.nan),
    "bad_qvel": lambda d: d.qvel.__setitem__(slice(None), 1e12),
    "bad_qacc": lambda d: d.qfrc_applied.__setitem__(slice(None), 1e20),
}
STEPS = (1, 2, 3, 17, 60)
"""Episode steps at which a blow-up is forced (1: the first step after a reset, when MuJoCo's clock starts at 0)."""


def test_every_forced_blow_up_is_flagged_at_any_step(caplog):
    flagged, forced = 0, 0
    env = make("Reacher", episode_steps=100)
    rng = np.random.default_rng(0)
    with caplog.at_level(logging.ERROR, logger="hrlp.arm.env"):  # the env logs each one as a warning
        for kind, force in BLOW_UPS.items():
            for at in STEPS:
                env.reset(seed=at)
                for _ in range(at - 1):
                    _, _, _, truncated, info = env.step(rng.uniform(-1, 1, 9))
                    assert not info.get("physics_unstable") and not truncated  # no false alarm before it
                force(env.physics.data)
                _, reward, terminated, truncated, info = env.step(np.zeros(9))
                forced += 1
                ok = truncated and not terminated and info.get("physics_unstable") and info["physics_warnings"][kind] >= 1
                flagged += bool(ok)
                assert ok, (kind, at, info)
                assert reward == 0.0
    assert flagged == forced == len(BLOW_UPS) * len(STEPS)


@pytest.mark.parametrize("kind", sorted(BLOW_UPS))
def test_arm_physics_flags_a_blow_up_on_the_first_step_after_a_reset(kind):
    physics = ArmPhysics()
    physics.reset()
    physics.forward()
    assert physics.data.time == 0.0
    BLOW_UPS[kind](physics.data)
    assert not physics.step(np.zeros(9))  # the simulated clock alone cannot tell: MuJoCo set it back to 0, then stepped
    assert physics.instability_warnings()[kind] >= 1
    # Flagged once: the next, ordinary step is stable again; a second blow-up right after is flagged again.
    assert physics.step(np.zeros(9))
    BLOW_UPS[kind](physics.data)
    assert not physics.step(np.zeros(9))


def test_ordinary_random_torques_raise_no_false_alarm():
    env = make("Gripper", episode_steps=300)
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(300):
        *_, truncated, info = env.step(rng.uniform(-1, 1, 9))
        assert not info.get("physics_unstable")
    assert truncated
