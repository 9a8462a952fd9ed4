"""Every MuJoCo call whose form or result differs between the versions hrlp supports (3.3 to 4.0), in one place.

What differs, measured on 3.3.7, 3.11.0 and 4.0.1 (docs/reliability.md, "MuJoCo versions"):

- ``mj_fullM`` takes ``(m, d, dst)`` from 3.10 on and ``(m, dst, d.qM)`` before: :func:`full_inertia`.
- The contact margin of a geom pair is the *sum* of the two geoms' margins on 3.11 and 4.0, their *maximum* on 3.3
  (the arm's capsule rests 1 mm lower on 3.3, and the shipped skills, trained under the sum, miss their marks):
  :func:`sum_contact_margins` makes every version compute the sum.
- A free body spinning about an axis that is not one of its principal axes: 3.11 and 4.0 update its angular velocity by
  other than ``h * qacc`` (the 3.11 changelog replaced the midpoint integration of free bodies), 3.3 by exactly that.
  There is no option to choose, so trajectories in which the capsule spins (pushed by a finger) part after the first
  such step; :func:`free_body_spin_as_4_0` says which rule this MuJoCo has, for the tests that replay recorded ones.
- ``Renderer.__del__`` of 3.3 reads an OpenGL context that a failed ``__init__`` never made (a second traceback at
  exit): :func:`open_renderer`.
- MuJoCo's own warnings ("Nan, Inf or huge value in QACC at DOF 13. The simulation is unstable.") are printed
  (``WARNING: ...``, to stdout on 3.3) and appended to ``MUJOCO_LOG.TXT`` in the working directory by every version:
  :func:`route_warnings` (called when this module is imported) sends them to the logger ``hrlp.mujoco`` instead, once
  per kind.
"""

from __future__ import annotations

import functools
import logging
import re
import threading
from typing import Literal

import mujoco
import numpy as np

log = logging.getLogger("hrlp.mujoco")

#: ``mj_fullM(m, d, dst)`` from MuJoCo 3.10 on; ``mj_fullM(m, dst, M)`` (the sparse ``d.qM``) before.
FULLM_TAKES_DATA = tuple(int(x) for x in mujoco.__version__.split(".")[:2]) >= (3, 10)


def full_inertia(model: mujoco.MjModel, data: mujoco.MjData, out: np.ndarray) -> np.ndarray:
    """The joint-space inertia matrix M(q) of ``data``'s state written into ``out [nv, nv]`` (and returned), with
    whichever signature this MuJoCo's ``mj_fullM`` has (:data:`FULLM_TAKES_DATA`)."""
    if FULLM_TAKES_DATA:
        mujoco.mj_fullM(model, data, out)
    else:  # MuJoCo before 3.10
        mujoco.mj_fullM(model, out, data.qM)
    return out


def open_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """``mujoco.Renderer(model, height, width)``; one whose OpenGL context could not be made is closed before the error
    goes on, so that no second traceback follows at exit (MuJoCo 3.3's ``Renderer.__del__`` reads the context it never
    made)."""
    renderer = mujoco.Renderer.__new__(mujoco.Renderer)
    try:
        renderer.__init__(model, height=height, width=width)  # type: ignore[misc]
    except BaseException:
        for name in ("_gl_context", "_mjr_context"):
            if not hasattr(renderer, name):
                setattr(renderer, name, None)
        raise
    return renderer


# --- contact margins ---------------------------------------------------------------------------------------------
# Two geoms of margins 0.001 and 0.003, 1.5 mm apart: the contact's margin says how this MuJoCo combines them.
_MARGIN_PROBE = """<mujoco><worldbody>
  <geom type="plane" size="1 1 0.1" margin="0.001"/>
  <body pos="0 0 0.1015"><freejoint/><geom type="sphere" size="0.1" margin="0.003"/></body>
</worldbody></mujoco>"""


@functools.cache
def contact_margin_rule() -> Literal["sum", "max"]:
    """How this MuJoCo combines the margins of two geoms into their contact's margin: ``"sum"`` (3.11 and 4.0, measured)
    or ``"max"`` (3.3). Found by colliding two geoms of different margins once (well under a millisecond), so no
    release number has to be known."""
    model = mujoco.MjModel.from_xml_string(_MARGIN_PROBE)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    if data.ncon != 1:  # pragma: no cover - a MuJoCo that finds no contact within the margin
        raise RuntimeError(f"MuJoCo {mujoco.__version__}: the contact-margin probe found {data.ncon} contacts, not 1")
    margin = float(data.contact[0].includemargin)
    if abs(margin - 0.004) < 1e-9:
        return "sum"
    if abs(margin - 0.003) < 1e-9:
        return "max"
    raise RuntimeError(  # pragma: no cover - a rule neither 3.3 nor 4.0 has
        f"MuJoCo {mujoco.__version__} combines contact margins 0.001 and 0.003 into {margin}: neither their sum nor max"
    )


def sum_contact_margins(model: mujoco.MjModel) -> mujoco.MjModel:
    """Make ``model`` (in place, and returned) give every geom pair the contact margin ``margin1 + margin2``, as MuJoCo
    3.11 and 4.0 do, on a MuJoCo that takes their maximum (3.3). There every colliding geom's margin is doubled, which
    is the sum exactly when they all share one margin and no gap; a model that does not raises ValueError. A no-op
    where MuJoCo sums the margins itself."""
    if contact_margin_rule() == "sum":
        return model
    colliding = (model.geom_contype | model.geom_conaffinity) != 0
    margins = np.unique(model.geom_margin[colliding])
    if len(margins) > 1 or np.any(model.geom_gap[colliding] != 0):
        raise ValueError(
            f"MuJoCo {mujoco.__version__} takes the larger of two geoms' contact margins, later versions their sum; "
            f"hrlp can make the two agree only for geoms of one margin and no gap (margins here: {margins.tolist()})"
        )
    model.geom_margin[colliding] *= 2
    return model


# A 2:1:0.4 box spinning at (3, 2, 1) rad/s without gravity: one implicitfast step.
_SPIN_PROBE = """<mujoco><option integrator="implicitfast" gravity="0 0 0"/><worldbody>
  <body><freejoint/><geom type="box" size="0.1 0.05 0.02" mass="1"/></body>
</worldbody></mujoco>"""


@functools.cache
def free_body_spin_as_4_0() -> bool:
    """Whether this MuJoCo integrates a spinning free body as 3.11 and 4.0 do (measured: its angular velocity changes by
    other than ``timestep * qacc`` in a step) rather than as 3.3 does (by exactly that). Found by stepping a spinning box
    once (well under a millisecond). States recorded under one rule cannot be replayed under the other once a free body
    spins: in a Gripper episode of the shipped ``gripper-clearance`` the capsule's angular velocity parted by 7e-3 rad/s
    in the substep after a finger first touched it."""
    model = mujoco.MjModel.from_xml_string(_SPIN_PROBE)
    data = mujoco.MjData(model)
    data.qvel[3:6] = (3.0, 2.0, 1.0)
    before = data.qvel[3:6].copy()
    mujoco.mj_step(model, data)
    change = (data.qvel[3:6] - before) / model.opt.timestep
    return not np.allclose(change, data.qacc[3:6], rtol=1e-9, atol=1e-12)


# --- MuJoCo's warnings -------------------------------------------------------------------------------------------
_seen: set[str] = set()
_seen_lock = threading.Lock()  # the rollout backend steps worlds on several threads
_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


def warning_kind(message: str) -> str:
    """The kind of a MuJoCo warning: its text with every number replaced by ``#`` (``... in QACC at DOF #. The
    simulation is unstable. Time = #.``), so that the same warning at another DOF or time is the same kind."""
    return _NUMBER.sub("#", message)


def _on_warning(message: str) -> None:
    """MuJoCo's warning handler while :func:`route_warnings` is in place: the first warning of each kind is logged."""
    kind = warning_kind(message)
    with _seen_lock:
        if kind in _seen:
            return
        _seen.add(kind)
    log.warning("MuJoCo: %s (shown once; later warnings of this kind are not)", message.strip())


def route_warnings() -> bool:
    """Send MuJoCo's warnings to the logger ``hrlp.mujoco`` (the first of each kind, :func:`warning_kind`, per process)
    instead of MuJoCo's own stdout print and ``MUJOCO_LOG.TXT``. Leaves a handler someone else installed in place.
    Returns whether hrlp's handler is the one in place."""
    current = mujoco.get_mju_user_warning()
    if current is None:
        mujoco.set_mju_user_warning(_on_warning)
        return True
    return current is _on_warning


route_warnings()
