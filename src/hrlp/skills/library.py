"""The skill library on disk: one checkpoint directory per skill (safetensors + JSON manifest).

A skill file may come from someone else, so loading one never runs code (safetensors, JSON; no pickle) and never
trusts it (docs/reliability.md, "Skill files from someone else"). Every way in -- :meth:`SkillLibrary.load`,
:meth:`SkillLibrary.manifest`, :func:`load_skill`, ``hrlp skills list/show`` and ``--skills`` -- makes the same checks,
and each failure is one line naming the skill:

* the name is a plain entry name (``..``, ``/abs/path`` and ``a/b`` are refused), and the entry is a directory inside
  the library (a symbolic link may point to another place in the library, never out of it);
* both files are regular files, opened without following links and without blocking (a FIFO or ``/dev/zero`` is
  refused at once), no larger than :data:`SKILL_LIMITS`, the manifest at most 16 levels deep, and the weights' sha256
  is the manifest's;
* the manifest's numbers are checked by its format (:class:`SkillFormat`: a policy on any environment's,
  :data:`POLICY_FORMAT`, here; a domain's own, registered through the :data:`DOMAINS_GROUP` entry point, as the arm's,
  :mod:`hrlp.arm.skill_files`, whose layout is 24 numbers + the parameters + the named features, 9 torques), against
  bounds (``k`` an integer from 1 to :data:`MAX_K`), and against the tensors' dtypes and shapes in the safetensors
  header, before any tensor or network is allocated: every weight is floating point and its shape is the one the
  manifest's network needs;
* every weight and statistic is finite (no NaN or inf) and the normaliser's variances are non-negative.

The library lives in ``$HRLP_SKILLS`` or ``~/.hrlp/skills``; each domain's shipped skills are searched after it.
"""

from __future__ import annotations

import math
import os
import re
import stat
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from hrlp.checkpoint import (
    CheckpointError,
    ReadLimits,
    TensorInfo,
    load_module,
    read_checkpoint,
    save_checkpoint,
)
from hrlp.domains import DOMAINS_GROUP, load_domains
from hrlp.paths import default_library_root
from hrlp.policies.mlp import GaussianPolicy, NumpyMLP, mlp
from hrlp.policies.normalizer import RunningNormalizer
from hrlp.skills.core import ParamBox, Skill
from hrlp.skills.policy import PolicySkill, check_bind

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
#: Bounds on a skill's files: a manifest is about 2 KB and 5 levels deep, the weights of a 64x64 skill 27 KB.
SKILL_LIMITS = ReadLimits(max_meta_bytes=1 << 20, max_weights_bytes=64 << 20, max_json_depth=16)
#: Largest default duration ``k`` of a skill, in low-level steps (the paper's: 8, 10, 15; an episode: at most 1,000).
MAX_K = 10_000
#: Safetensors dtypes a skill's weights and statistics may have: floating point (integer weights act as zeros).
FLOAT_DTYPES = ("F16", "BF16", "F32", "F64")


class SkillProblem(CheckpointError):
    """Something wrong inside a skill's files, said without the skill's name (the library adds it)."""


def check_skill_name(name: str) -> None:
    """Raise ValueError unless ``name`` is a plain entry name of a skill library (no path: ``..``, ``/x``, ``a/b``)."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"skill name {name!r} is not a plain entry name of a skill library: use letters, digits, "
                         "'_', '-', '.', starting with a letter or digit, at most 64 characters")  # fmt: skip


def search_roots(library: str | Path | None = None) -> list[Path]:
    """Where :func:`load_skill` looks, in order: ``library`` (if given), the user's library, the shipped skills."""
    return ([Path(library)] if library is not None else []) + [default_library_root(), *shipped_roots()]


def locate_skill(name: str, roots: Sequence[str | Path]) -> SkillLibrary:
    """The first library of ``roots`` with an entry ``name``. Raises ValueError for a name that is not a plain entry
    name, or one found nowhere (naming the entries of every root)."""
    check_skill_name(name)
    libraries = [SkillLibrary(Path(root)) for root in roots]
    for lib in libraries:
        if name in lib.names():
            return lib
    known = sorted({n for lib in libraries for n in lib.names()})
    where = ", ".join(str(lib.root) for lib in libraries)
    raise ValueError(f"no skill {name!r} in {where} (known: {', '.join(known) or 'none'})")


def load_skill(name: str, library: str | Path | None = None) -> Skill:
    """The named skill, frozen, from ``library`` (if given), the user's library, or the shipped skills, in that order."""
    return locate_skill(name, search_roots(library)).load(name)


def _short(value: Any, width: int = 40) -> str:
    """``repr(value)`` on one line, cut to ``width`` characters."""
    text = " ".join(repr(value).split()) if not isinstance(value, BaseException) else " ".join(str(value).split())
    return text if len(text) <= width else text[: width - 3] + "..."


def _integer(m: dict[str, Any], key: str, low: int, high: int, what: str) -> int:
    value = m.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        bound = f"from {low} to {high:,}" if low != high else f"{low}"
        got = "nothing" if key not in m else f"{_short(value)} ({type(value).__name__})"
        raise SkillProblem(f"manifest's {key!r} ({what}) must be an integer {bound}, got {got}")
    return value


@dataclass(frozen=True)
class SkillFormat:
    """How a library reads one kind of skill file: ``check(manifest)`` checks every number of a manifest (raising
    :class:`SkillProblem`, one line) before any tensor is read; ``build(name, tensors, manifest, sha256)`` makes the frozen
    skill from checked files. Every format stores a :class:`~hrlp.policies.mlp.GaussianPolicy`'s weights (a
    :data:`POLICY_FORMAT` manifest whose ``actor`` is ``squashed``: a Box :class:`~hrlp.policies.sac.SACActor`'s) and its
    normaliser (:func:`_expected_tensors`)."""

    check: Callable[[dict[str, Any]], object]
    build: Callable[[str, dict[str, torch.Tensor], dict[str, Any], str], Skill]


#: The ``format`` of a skill file holding a policy trained on any Gymnasium environment (a :class:`PolicySkill`).
POLICY_FORMAT = "policy"
#: A policy skill's ``actor``: the Gaussian of TRPO and PPO runs (the default), or SAC's tanh-squashed one.
GAUSSIAN_ACTOR, SQUASHED_ACTOR = "gaussian", "squashed"
#: The format of a manifest that names none: skill files were the arm's before formats had names (:mod:`hrlp.arm`).
UNNAMED_FORMAT = "arm"
_FORMATS: dict[str, SkillFormat] = {}
_SHIPPED: list[Path] = []


def register_format(name: str, fmt: SkillFormat) -> None:
    """Read manifests whose ``format`` is ``name`` with ``fmt`` (a domain's own skill files)."""
    _FORMATS[name] = fmt


def register_shipped(root: Path) -> None:
    """Search ``root`` after the user's library (a domain's shipped skills)."""
    if root not in _SHIPPED:
        _SHIPPED.append(root)


def shipped_roots() -> list[Path]:
    """The shipped skills of every domain, in the order they registered."""
    load_domains()
    return list(_SHIPPED)


def _format(m: dict[str, Any]) -> SkillFormat:
    load_domains()
    name = m.get("format", UNNAMED_FORMAT)
    if name not in _FORMATS:
        raise SkillProblem(f"skill file of unknown format {_short(name)} (known: {', '.join(sorted(_FORMATS))})")
    return _FORMATS[name]


def _check_any(m: dict[str, Any]) -> None:
    """A manifest checked by its format's own check; raises :class:`SkillProblem`."""
    _format(m).check(m)


def _check_policy_manifest(m: dict[str, Any]) -> tuple[ParamBox, int, tuple[int, ...]]:
    """``(params, k, hidden)`` of a policy skill's manifest, whose every number is checked: its observation parts
    (names and widths, summing to ``obs_dim``), the part its parameters replace and their box, its action bounds
    (``act_dim`` finite pairs), its early end, its network and normaliser; raises :class:`SkillProblem`."""
    if m.get("kind") != "skill":
        raise SkillProblem(f"not a skill (kind {_short(m.get('kind'))})")
    k = _integer(m, "k", 1, MAX_K, "default duration")
    parts = m.get("parts")
    if not isinstance(parts, list) or not parts or not all(
        isinstance(p, list) and len(p) == 2 and isinstance(p[0], str) and isinstance(p[1], int) and not isinstance(p[1], bool)
        and 0 < p[1] <= 1 << 20 for p in parts
    ):  # fmt: skip
        raise SkillProblem(f"manifest's 'parts' must be a list of [name, width] pairs, got {_short(parts)}")
    names = [p[0] for p in parts]
    if len(set(names)) != len(names):
        raise SkillProblem(f"manifest's 'parts' name a part twice ({', '.join(names)})")
    obs_dim = sum(p[1] for p in parts)
    _integer(m, "obs_dim", obs_dim, obs_dim, "observation size, the widths of its parts")
    act_dim = _integer(m, "act_dim", 1, 1 << 16, "action size")
    param_part = m.get("param_part")
    if param_part is not None and param_part not in names:
        raise SkillProblem(f"manifest's 'param_part' {_short(param_part)} is not one of its parts ({', '.join(names)})")
    try:
        box = ParamBox.from_json(m.get("param") or {})
    except ValueError as e:
        raise SkillProblem(f"manifest's 'param': {_short(e, 120)}") from None
    width = dict(map(tuple, parts)).get(param_part, 0) if param_part else 0
    if box.dim != width:
        raise SkillProblem(f"manifest's parameter box has {box.dim} numbers, its parameter part {width}")
    for key in ("action_low", "action_high"):
        v = m.get(key)
        if not isinstance(v, list) or len(v) != act_dim or not all(_number(x) and math.isfinite(x) for x in v):
            raise SkillProblem(f"manifest's {key!r} must be {act_dim} finite numbers, got {_short(v)}")
    if any(lo > hi for lo, hi in zip(m["action_low"], m["action_high"], strict=True)):
        raise SkillProblem("manifest's action_low exceeds its action_high")
    done = m.get("done")
    if done is not None and (not isinstance(done, dict) or not isinstance(done.get("part"), str) or not done["part"]
                             or not (_number(done.get("within")) and 0 < done["within"] < math.inf)):  # fmt: skip
        raise SkillProblem(f"manifest's 'done' must be {{part: a part name, within: a positive distance}}, got "
                            f"{_short(done)}")  # fmt: skip
    bind = m.get("bind")
    if bind is not None and not (isinstance(bind, dict) and all(isinstance(v, list) for v in bind.values())):
        raise SkillProblem(f"manifest's 'bind' must map its parts to lists of part names, got {_short(bind)}")
    try:
        check_bind(bind, names, param_part, "file")
    except ValueError as e:
        raise SkillProblem(f"manifest's 'bind': {str(e).removeprefix('skill file: ')}") from None
    if m.get("actor", GAUSSIAN_ACTOR) not in (GAUSSIAN_ACTOR, SQUASHED_ACTOR):
        raise SkillProblem(f"manifest's 'actor' must be {GAUSSIAN_ACTOR} or {SQUASHED_ACTOR}, got {_short(m.get('actor'))}")
    hidden = _check_network(m, obs_dim)
    return box, k, hidden


def _check_network(m: dict[str, Any], obs_dim: int) -> tuple[int, ...]:
    """The manifest's hidden widths, normaliser settings and training record, checked; returns ``hidden``."""
    hidden = m.get("hidden")
    if not isinstance(hidden, list) or not all(isinstance(h, int) and not isinstance(h, bool) and h > 0 for h in hidden):
        raise SkillProblem(f"manifest's 'hidden' must be a list of positive layer widths, got {_short(hidden)}")
    norm = m.get("normalizer")
    if not isinstance(norm, dict) or norm.get("shape") != [obs_dim]:
        raise SkillProblem(f"manifest's 'normalizer' must be an object with shape [{obs_dim}], got {_short(norm)}")
    clip, eps, frozen = norm.get("clip"), norm.get("eps", 1e-8), norm.get("frozen", False)
    if not (clip is None or (_number(clip) and clip > 0)) or not (_number(eps) and eps >= 0) or not isinstance(frozen, bool):
        raise SkillProblem(f"manifest's normaliser settings are invalid (clip {_short(clip)}, eps {_short(eps)}, "
                            f"frozen {_short(frozen)})")  # fmt: skip
    trained = m.get("trained")
    if not isinstance(trained, dict) or not isinstance(trained.get("config"), dict):
        raise SkillProblem(f"manifest's 'trained' must be an object holding the training 'config', got {_short(trained)}")
    _integer(trained, "env_steps", 0, 2**62, "environment steps it was trained for")
    return tuple(hidden)


def _number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _expected_tensors(m: dict[str, Any]) -> dict[str, tuple[int, ...]]:
    """The shape of every tensor of the network and normaliser that a (checked) manifest describes."""
    obs_dim, act_dim, hidden = m["obs_dim"], m["act_dim"], list(m["hidden"])
    squashed = m.get("actor") == SQUASHED_ACTOR  # a SAC actor: means and log stds from one net, no log_std parameter
    widths = [obs_dim, *hidden, 2 * act_dim if squashed else act_dim]
    out: dict[str, tuple[int, ...]] = {} if squashed else {"policy.log_std": (act_dim,)}
    net = "policy.net" if squashed else "policy.mean_net"
    for i in range(len(widths) - 1):  # Linear, activation, Linear, activation, ..., Linear: linears at even indices
        out[f"{net}.{2 * i}.weight"] = (widths[i + 1], widths[i])
        out[f"{net}.{2 * i}.bias"] = (widths[i + 1],)
    out |= {"normalizer.count": (), "normalizer.mean": (obs_dim,), "normalizer.var": (obs_dim,)}
    return out


def _check_header(m: dict[str, Any], header: dict[str, TensorInfo]) -> None:
    """The manifest against the tensors' names, dtypes and shapes in the safetensors header, before any is built."""
    _check_any(m)
    expected = _expected_tensors(m)
    network = f"obs_dim {m['obs_dim']}, hidden {m['hidden']}, act_dim {m['act_dim']}"
    missing, unexpected = sorted(set(expected) - set(header)), sorted(set(header) - set(expected))
    if missing or unexpected:
        said = ", ".join(p for p in (f"missing {', '.join(missing)}" if missing else "",
                                     f"unexpected {', '.join(unexpected)}" if unexpected else "") if p)  # fmt: skip
        said = said if len(said) <= 160 else said[:157] + "..."
        raise SkillProblem(f"its weights do not fit the network its manifest describes ({network}): {said}")
    for name, info in sorted(header.items()):
        if info.dtype not in FLOAT_DTYPES:
            raise SkillProblem(f"{name} is {_short(info.dtype)}; a skill's weights must be floating point "
                                f"({', '.join(FLOAT_DTYPES)})")  # fmt: skip
        if info.shape != expected[name]:
            raise SkillProblem(f"{name} has shape {list(info.shape)} in its weights, {list(expected[name])} in the "
                                f"network its manifest describes ({network})")  # fmt: skip


def _check_values(tensors: dict[str, torch.Tensor]) -> None:
    """Every weight and statistic finite, the normaliser's variances and count non-negative."""
    for name, tensor in sorted(tensors.items()):
        bad = ~torch.isfinite(tensor)
        if bool(bad.any()):
            raise SkillProblem(f"{name} holds NaN or inf ({int(bad.sum())} of {tensor.numel()} values)")
    for name in ("normalizer.var", "normalizer.count"):
        if bool((tensors[name] < 0).any()):
            raise SkillProblem(f"{name} is negative")


def _entry_kind(path: Path) -> str:
    try:
        mode = os.stat(path).st_mode
    except OSError as e:
        return f"cannot be read: {e.strerror}"
    for test, kind in ((stat.S_ISREG, "a regular file"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a device"),
                       (stat.S_ISSOCK, "a socket")):  # fmt: skip
        if test(mode):
            return kind
    return "not a directory"


class SkillLibrary:
    """Named skills in a directory: ``add`` from a finished run, ``load`` frozen, ``list`` and ``manifest``."""

    def __init__(self, root: Path | None = None) -> None:
        self.root = Path(root) if root is not None else default_library_root()

    def names(self) -> list[str]:
        """Names of the library's entries, sorted: everything in it but regular files (a README) and names starting with
        '.', whether or not it holds a valid skill (:meth:`manifest` and :meth:`load` say what is wrong with one)."""
        try:
            with os.scandir(self.root) as entries:
                return sorted(e.name for e in entries if not e.name.startswith(".") and not e.is_file(follow_symlinks=False))
        except OSError:  # no library (yet), or not a directory
            return []

    def _known(self) -> str:
        return ", ".join(self.names()) or "none"

    def entry(self, name: str) -> Path:
        """The directory of the skill ``name``, checked: a plain entry name, an entry of this library, a directory,
        not a symbolic link out of the library. Raises ValueError (CheckpointError for a broken entry)."""
        check_skill_name(name)
        path = self.root / name
        if not os.path.lexists(path):
            raise ValueError(f"no skill {name!r} in {self.root} (known: {self._known()})")
        if path.is_symlink():
            target, root = os.path.realpath(path), os.path.realpath(self.root)
            if os.path.commonpath([target, root]) != root or target == root:
                raise CheckpointError(f"skill {name!r} ({path}): a symbolic link out of the library (-> "
                                      f"{os.readlink(path)}); copy the skill into {self.root} instead")  # fmt: skip
        if not path.is_dir():
            raise CheckpointError(f"skill {name!r} ({path}): not a skill directory ({_entry_kind(path)})")
        return path

    def _read(self, name: str) -> tuple[dict[str, torch.Tensor], dict[str, Any], str]:
        """``(tensors, manifest, sha256)`` of the skill ``name``, after every check of the module docstring."""
        path = self.entry(name)
        try:
            tensors, m, sha256 = read_checkpoint(path, limits=SKILL_LIMITS, before_tensors=_check_header)
            _check_values(tensors)
        except SkillProblem as e:
            raise CheckpointError(f"skill {name!r} ({path}): {e}") from None
        except CheckpointError as e:
            raise CheckpointError(f"skill {name!r}: {e}") from None
        return tensors, m, sha256

    def manifest(self, name: str) -> dict[str, Any]:
        """The manifest of the skill ``name`` (with its content hash under ``sha256``), once the skill has passed
        every check that :meth:`load` makes; raises the same one-line errors."""
        _, m, sha256 = self._read(name)
        return {**m, "sha256": sha256}

    def load(self, name: str) -> Skill:
        """The named skill, frozen. Raises a one-line error naming the skill for a missing, tampered, truncated or
        degenerate one (module docstring); the network is built only from a manifest its tensors agree with."""
        tensors, m, sha256 = self._read(name)
        try:
            return _format(m).build(name, tensors, m, sha256)
        except ValueError as e:  # not expected after the checks; named all the same
            raise CheckpointError(f"skill {name!r} ({self.root / name}): {_short(e, 200)}") from None

    def save(self, name: str, tensors: dict[str, torch.Tensor], manifest: dict[str, Any], overwrite: bool = False) -> Path:
        """Write the skill ``name`` from its tensors and manifest (a :data:`POLICY_FORMAT` one unless the manifest names
        another format), after the checks :meth:`load` makes; returns its directory. Refuses to replace a skill unless
        ``overwrite``."""
        check_skill_name(name)
        target = self.root / name
        if target.exists() and not overwrite:
            raise ValueError(f"skill {name!r} already exists in {self.root}; pass overwrite to replace it")
        m = {"format": POLICY_FORMAT, **manifest, "kind": "skill", "name": name}
        try:
            _check_any(m)
        except SkillProblem as e:
            raise ValueError(f"skill {name!r}: {e}") from None
        return save_checkpoint(target, tensors, m)


def frozen_network(tensors: dict[str, torch.Tensor], m: dict[str, Any], hidden: tuple[int, ...]) -> tuple[
        GaussianPolicy, RunningNormalizer]:  # fmt: skip
    """The policy and frozen normaliser a checked manifest ``m`` describes, with ``tensors`` loaded into them."""
    policy = GaussianPolicy(m["obs_dim"], m["act_dim"], hidden)
    stats = {key.removeprefix("normalizer."): v for key, v in tensors.items() if key.startswith("normalizer.")}
    load_module("policy", policy, tensors)
    norm = RunningNormalizer.from_config(m["normalizer"], stats)
    norm.freeze()
    return policy, norm


def _squashed_net(
    tensors: dict[str, torch.Tensor], obs_dim: int, hidden: tuple[int, ...], act_dim: int
) -> torch.nn.Sequential:
    """A SAC actor's network (ReLU layers, means then log stds) with the skill's weights loaded."""
    net = mlp(obs_dim, 2 * act_dim, hidden, torch.nn.ReLU)
    load_module("policy.net", net, tensors)
    return net


def _build_policy(name: str, tensors: dict[str, torch.Tensor], m: dict[str, Any], sha256: str) -> PolicySkill:
    """A policy skill (:data:`POLICY_FORMAT`) from its checked files: its mean action in NumPy on the frozen
    normaliser's output, clipped to its action bounds."""
    box, k, hidden = _check_policy_manifest(m)
    low, high = np.asarray(m["action_low"], np.float64), np.asarray(m["action_high"], np.float64)
    stats = {key.removeprefix("normalizer."): v for key, v in tensors.items() if key.startswith("normalizer.")}
    norm = RunningNormalizer.from_config(m["normalizer"], stats)
    norm.freeze()
    if m.get("actor") == SQUASHED_ACTOR:  # tanh of the means, mapped onto the action bounds (SACActor.act's mode)
        net = NumpyMLP(_squashed_net(tensors, m["obs_dim"], hidden, m["act_dim"]))
        act_dim, mid, half = m["act_dim"], (high + low) / 2, (high - low) / 2

        def act(x: np.ndarray) -> np.ndarray:
            return np.tanh(net(norm.normalize(x))[..., :act_dim]) * half + mid
    else:
        policy, _ = frozen_network(tensors, m, hidden)
        mean = NumpyMLP(policy.mean_net)

        def act(x: np.ndarray) -> np.ndarray:
            return mean(norm.normalize(x))

    done = m.get("done") or {}
    skill = PolicySkill(name, [tuple(p) for p in m["parts"]], m.get("param_part"), box, act, low, high, k=k,
                        done_part=done.get("part"), done_within=done.get("within"), bind=m.get("bind"))  # fmt: skip
    skill.content_hash = sha256
    return skill


register_format(POLICY_FORMAT, SkillFormat(_check_policy_manifest, _build_policy))


__all__ = [
    "DOMAINS_GROUP",
    "FLOAT_DTYPES",
    "GAUSSIAN_ACTOR",
    "MAX_K",
    "POLICY_FORMAT",
    "SKILL_LIMITS",
    "SQUASHED_ACTOR",
    "SkillFormat",
    "SkillLibrary",
    "SkillProblem",
    "check_skill_name",
    "default_library_root",
    "frozen_network",
    "load_skill",
    "locate_skill",
    "register_format",
    "register_shipped",
    "search_roots",
    "shipped_roots",
]
