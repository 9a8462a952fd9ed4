"""hrlp.mjcompat: known answers that hold on whatever MuJoCo is installed (CI runs them on 3.3.7 and 4.0.x)."""

import logging

import mujoco
import numpy as np
import pytest

from hrlp import mjcompat
from hrlp.arm.physics import ArmPhysics, PhysicsConfig, load_model


def test_full_inertia_is_the_matrix_mujoco_multiplies_by_on_any_version():
    p = ArmPhysics(PhysicsConfig())
    p.reset()
    p.data.qpos[:9] = np.linspace(-0.5, 0.5, 9)
    p.forward()
    nv = p.model.nv
    m = mjcompat.full_inertia(p.model, p.data, np.zeros((nv, nv)))
    columns, res = np.empty((nv, nv)), np.empty(nv)
    for i in range(nv):
        mujoco.mj_mulM(p.model, p.data, res, np.eye(nv)[i])  # M e_i, whatever mj_fullM's signature
        columns[:, i] = res
    np.testing.assert_allclose(m, columns, rtol=1e-12, atol=1e-14)
    assert np.allclose(m, m.T) and (np.linalg.eigvalsh(m) > 0).all()


def test_the_arms_contacts_have_the_summed_margin_and_the_capsule_rests_at_one_height_on_any_version():
    assert mjcompat.contact_margin_rule() in ("sum", "max")
    model = load_model()
    data = mujoco.MjData(model)
    for _ in range(500):  # one simulated second: the capsule settles on the table
        mujoco.mj_step(model, data)
    assert data.ncon == 2 and all(c.includemargin == pytest.approx(0.002) for c in data.contact)  # 0.001 + 0.001
    # Measured: 0.026984304 on 4.0.1 and, with the margins summed, on 3.3.7 (0.025984304 there without: 1 mm lower).
    assert data.qpos[model.jnt_qposadr[model.joint("object").id] + 2] == pytest.approx(0.026984304, abs=1e-9)


def test_where_mujoco_takes_the_larger_margin_the_margins_are_doubled_or_refused(monkeypatch):
    monkeypatch.setattr(mjcompat, "contact_margin_rule", lambda: "max")  # MuJoCo 3.3's rule, on any version
    model = mujoco.MjModel.from_xml_string(mjcompat._MARGIN_PROBE)
    mixed = model.geom_margin.copy()
    with pytest.raises(ValueError, match=r"one margin and no gap \(margins here: \[0\.001, 0\.003\]\)"):
        mjcompat.sum_contact_margins(model)
    np.testing.assert_array_equal(model.geom_margin, mixed)  # refused: left as it was
    model.geom_margin[:] = 0.001
    assert mjcompat.sum_contact_margins(model) is model
    np.testing.assert_array_equal(model.geom_margin, [0.002, 0.002])  # max(0.002, 0.002) = 0.001 + 0.001


@pytest.mark.parametrize(
    ("message", "kind"),
    [
        ("Nan, Inf or huge value in QACC at DOF 13. The simulation is unstable. Time = 0.0100.",
         "Nan, Inf or huge value in QACC at DOF #. The simulation is unstable. Time = #."),
        ("Too many contacts: 1.5e+03", "Too many contacts: #"),
    ],
)  # fmt: skip
def test_a_warnings_kind_is_its_text_without_its_numbers(message, kind):
    assert mjcompat.warning_kind(message) == kind


def test_mujocos_warnings_reach_the_hrlp_logger_once_per_kind_and_nothing_is_printed(monkeypatch, tmp_path, caplog, capfd):
    from hrlp.arm.batched import make_batched

    monkeypatch.chdir(tmp_path)  # where MuJoCo's own handler would write MUJOCO_LOG.TXT
    monkeypatch.setattr(mjcompat, "_seen", set())
    assert mjcompat.route_warnings()  # hrlp's handler is in place (importing hrlp.mjcompat put it there)
    caplog.set_level(logging.WARNING, logger="hrlp.mujoco")
    p = ArmPhysics()
    for dof in (3, 5):  # the same kind twice (ArmPhysics clears MuJoCo's counters, so MuJoCo warns each time)
        p.data.qvel[dof] = 1e12
        assert not p.step(np.zeros(9))
    worlds = make_batched("MoverPlain", 3, backend="rollout")  # stepped on MuJoCo's rollout threads
    worlds.reset(seed=0)
    state = worlds.get_state()
    for w in (0, 2):
        state["envs"][w]["physics"][1 + 16] = 1e12  # the first joint velocity (after time and 16 qpos)
    worlds.set_state(state)
    assert worlds.step(np.zeros((3, 9))).infos["physics_unstable"].tolist() == [True, False, True]
    records = [r for r in caplog.records if r.name == "hrlp.mujoco"]
    assert [r.getMessage() for r in records] == [
        "MuJoCo: Nan, Inf or huge value in QVEL at DOF 3. The simulation is unstable. Time = 0.0000. "
        "(shown once; later warnings of this kind are not)"
    ]
    p.data.qpos[0] = np.nan  # another kind: a bad position
    p.step(np.zeros(9))
    assert len([r for r in caplog.records if r.name == "hrlp.mujoco"]) == 2
    out, err = capfd.readouterr()
    assert "Nan, Inf" not in out + err and not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_a_warning_handler_installed_by_someone_else_is_left_in_place(monkeypatch):
    theirs = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(theirs.append)
    try:
        assert not mjcompat.route_warnings()
        assert mujoco.get_mju_user_warning() is not mjcompat._on_warning
    finally:
        mujoco.set_mju_user_warning(previous)
    assert mjcompat.route_warnings()


def test_the_probes_give_the_rules_measured_at_both_ends_of_the_supported_range():
    version = tuple(int(x) for x in mujoco.__version__.split(".")[:2])
    if (3, 3) < version < (3, 11):
        pytest.skip(f"MuJoCo {mujoco.__version__}: measured on 3.3.7, 3.11.0 and 4.0.1 only")
    expected = ("max", False) if version == (3, 3) else ("sum", True)
    assert (mjcompat.contact_margin_rule(), mjcompat.free_body_spin_as_4_0()) == expected
