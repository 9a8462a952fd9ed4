"""Deterministic actors read from Stable-Baselines3 ``.zip`` files, without unpickling anything.

**What is supported.** Files written by ``model.save(path)`` for SB3's PPO, SAC and TD3 with an ``MlpPolicy`` (a Box
observation, flattened) or a ``MultiInputPolicy`` (a Dict of Box observations, each flattened and concatenated in the
Dict's key order, SB3's ``CombinedExtractor``), a one-dimensional Box action, any ``net_arch``, and one of the
activations ``ReLU``, ``Tanh``, ``ELU``, ``LeakyReLU``, ``GELU``, ``SiLU``. Refused, each with one line naming the file:
other algorithms (A2C, DQN, DDPG, sb3-contrib's), CNN or custom feature extractors, custom policy classes, image-like
observations (a 3-D ``uint8`` Box, or any 3-D Box inside a Dict, which SB3 would feed to a CNN or divide by 255),
non-Box sub-spaces, multi-dimensional actions, tensors whose shapes do not chain into the expected network,
non-finite weights, and zip members over :data:`MAX_MEMBER_BYTES` (checked from the zip's directory before reading).
Observation normalisation (``VecNormalize``, saved in a separate file) is not part of the ``.zip`` and not applied.

**Why nothing is unpickled.** An SB3 ``.zip`` holds ``data`` (JSON, in which objects that are not JSON are cloudpickled
under ``":serialized:"``) and ``policy.pth`` (a torch state dict). Unpickling either runs whatever code the file
names, so this module never does: ``data`` is read with :func:`json.loads` and only its plain fields are used (the
spaces' ``_shape``, ``dtype``, ``low``, ``high`` and, for a Dict, the ``spaces`` text; the readable policy_kwargs);
``policy.pth`` is read with torch's weights-only loader, which refuses any pickled global beyond tensors and plain
containers. Where a fact is only inside a ``":serialized:"`` blob (the policy class, the activation class), the blob
is base64-decoded and *disassembled* with :func:`pickletools.genops` to list the ``module.Name`` globals it refers to:
a byte-level scan that imports and calls nothing.

**Which algorithm.** The policy class (``stable_baselines3.sac.policies.SACPolicy``, ``...td3.policies.TD3Policy``,
``...common.policies.ActorCriticPolicy`` and their MultiInput variants) together with hyperparameters only one
algorithm stores: PPO's ``clip_range`` and ``n_epochs`` (A2C shares PPO's policy class but not these), SAC's
``ent_coef`` and ``target_entropy``, TD3's ``policy_delay`` (DDPG saves TD3's policy with its fixed ``policy_delay=1,
target_noise_clip=0, target_policy_noise=0.1`` and is refused), and the actor's tensors in ``policy.pth``.

**The deterministic action** (``model.predict(obs, deterministic=True)``), computed in float64 after rounding the
observation to float32 as SB3 does:

- PPO: the Gaussian mean ``action_net(mlp(obs))`` clipped to ``[low, high]``; with gSDE and ``squash_output=True``,
  ``tanh`` of the mean rescaled from ``[-1, 1]`` to ``[low, high]``.
- SAC: ``tanh(mu(mlp(obs)))`` rescaled to ``[low, high]`` (with gSDE the mean is first clipped to ``±clip_mean``).
- TD3: the actor ``mu`` ends in ``tanh``; its output rescaled to ``[low, high]``.
"""

from __future__ import annotations

import base64
import binascii
import io
import json
import math
import pickletools
import re
import zipfile
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

__all__ = ["MAX_MEMBER_BYTES", "SUPPORTED_ALGOS", "SB3Policy", "load_sb3"]

#: Largest uncompressed size of a zip member this module reads (``data``, ``policy.pth``), bytes.
MAX_MEMBER_BYTES = 256 * 1024 * 1024
#: The algorithms :func:`load_sb3` reads.
SUPPORTED_ALGOS = ("PPO", "SAC", "TD3")

_SUPPORTED = ", ".join(SUPPORTED_ALGOS)
_ACTIVATION_MODULE = "torch.nn.modules.activation"
_DEFAULT_ACTIVATION = {"PPO": "Tanh", "SAC": "ReLU", "TD3": "ReLU"}
_TORCH_LAYERS = "stable_baselines3.common.torch_layers"

#: (policy module, class name) -> (algorithm family, Dict observation).
_POLICY_CLASSES: dict[tuple[str, str], tuple[str, bool]] = {
    ("stable_baselines3.common.policies", "ActorCriticPolicy"): ("PPO", False),
    ("stable_baselines3.common.policies", "MultiInputActorCriticPolicy"): ("PPO", True),
    ("stable_baselines3.sac.policies", "SACPolicy"): ("SAC", False),
    ("stable_baselines3.sac.policies", "MultiInputPolicy"): ("SAC", True),
    ("stable_baselines3.td3.policies", "TD3Policy"): ("TD3", False),
    ("stable_baselines3.td3.policies", "MultiInputPolicy"): ("TD3", True),
}

#: policy_kwargs each algorithm's policy accepts; those that change the actor are checked, the rest do not matter here.
_COMMON_KWARGS = {
    "net_arch",
    "activation_fn",
    "features_extractor_class",
    "features_extractor_kwargs",
    "normalize_images",
    "optimizer_class",
    "optimizer_kwargs",
    "share_features_extractor",
}
_KNOWN_KWARGS = {
    "PPO": _COMMON_KWARGS | {"ortho_init", "use_sde", "log_std_init", "full_std", "use_expln", "squash_output"},
    "SAC": _COMMON_KWARGS | {"use_sde", "log_std_init", "use_expln", "clip_mean", "n_critics"},
    "TD3": _COMMON_KWARGS | {"n_critics"},
}


def _gelu(x: np.ndarray) -> np.ndarray:
    from scipy.special import erf

    return 0.5 * x * (1.0 + erf(x / math.sqrt(2.0)))


def _silu(x: np.ndarray) -> np.ndarray:
    from scipy.special import expit

    return x * expit(x)


#: torch's activations with their default arguments (an activation *class* is stored, so defaults are what ran).
_ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "ReLU": lambda x: np.maximum(x, 0.0),
    "Tanh": np.tanh,
    "ELU": lambda x: np.where(x > 0.0, x, np.expm1(np.minimum(x, 0.0))),
    "LeakyReLU": lambda x: np.where(x >= 0.0, x, 0.01 * x),
    "GELU": _gelu,
    "SiLU": _silu,
}

_Layer = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True, eq=False)
class SB3Policy:
    """The deterministic actor of an SB3 PPO, SAC or TD3 policy, as plain float64 arrays (see the module docstring).

    Build it with :func:`load_sb3`. ``act`` takes the observation flattened: for a Dict observation the parts of
    ``obs_parts`` concatenated in that order (SB3's order, the Dict's key order), each part flattened C-style.
    """

    algo: str
    """"PPO", "SAC" or "TD3"."""
    obs_parts: tuple[tuple[str, int], ...]
    """(key, flat width) in SB3's concatenation order; a Box observation is ``(("observation", width),)``."""
    obs_is_dict: bool
    action_low: np.ndarray
    """[A] float64: the env's lower action bounds as stored (float32 values, exactly)."""
    action_high: np.ndarray
    """[A] float64: the upper action bounds."""
    _hidden: tuple[_Layer, ...] = field(repr=False)
    _output: _Layer = field(repr=False)
    _activation: str = field(repr=False)
    _squash: bool = field(repr=False)
    _clip_mean: float | None = field(repr=False)

    @property
    def obs_dim(self) -> int:
        """Width of the flattened observation ``act`` takes."""
        return sum(width for _, width in self.obs_parts)

    @property
    def act_dim(self) -> int:
        """Number of action components."""
        return int(self.action_low.shape[0])

    @property
    def activation(self) -> str:
        """Name of the hidden layers' activation (a torch.nn class name)."""
        return self._activation

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Deterministic actions for observations ``[N, obs_dim]`` (or one ``[obs_dim]``): ``[N, A]`` (or ``[A]``) float64.

        Equal, up to float32 rounding in SB3's torch forward pass, to ``model.predict(obs, deterministic=True)[0]``.
        """
        x = np.asarray(obs)
        single = x.ndim == 1
        if single:
            x = x[None, :]
        if x.ndim != 2 or x.shape[1] != self.obs_dim:
            raise ValueError(f"{self.algo} policy: expected observations of shape [N, {self.obs_dim}], got {np.shape(obs)}")
        # SB3 casts observations to float32 before its forward pass; round the same way, then compute in float64.
        h = x.astype(np.float32).astype(np.float64)
        activation = _ACTIVATIONS[self._activation]
        for weight, bias in self._hidden:
            h = activation(h @ weight.T + bias)
        weight, bias = self._output
        mean = h @ weight.T + bias
        if self._squash:
            if self._clip_mean is not None:
                mean = np.clip(mean, -self._clip_mean, self._clip_mean)
            scaled = np.tanh(mean)
            actions = self.action_low + 0.5 * (scaled + 1.0) * (self.action_high - self.action_low)
        else:
            actions = np.clip(mean, self.action_low, self.action_high)
        return actions[0] if single else actions


def load_sb3(path: str | Path) -> SB3Policy:
    """Read the deterministic actor of an SB3 PPO, SAC or TD3 ``.zip`` without unpickling anything.

    Raises ``ValueError(f"{path}: <problem>")``, one line, for anything it cannot read exactly (see the module
    docstring for what is supported).
    """
    path = Path(path)
    data_bytes, policy_bytes = _read_members(path)
    try:
        data = json.loads(data_bytes)
    except (ValueError, RecursionError):
        _fail(path, "'data' is not JSON (not an SB3 save file?)")
    if not isinstance(data, dict):
        _fail(path, "'data' is not a JSON object (not an SB3 save file?)")

    algo, dict_policy = _identify_algo(path, data)
    obs_parts, obs_is_dict = _observation_parts(path, data.get("observation_space"))
    if obs_is_dict != dict_policy:
        _fail(path, f"the policy class and the observation space disagree (Dict observation: {obs_is_dict})")
    low, high = _action_bounds(path, data.get("action_space"))

    kwargs, kwargs_globals = _policy_kwargs(path, data.get("policy_kwargs"))
    unknown = sorted(set(kwargs) - _KNOWN_KWARGS[algo])
    if unknown:
        _fail(path, f"policy_kwargs {', '.join(map(repr, unknown))} not understood for {algo}")
    _check_extractor(path, kwargs, kwargs_globals, obs_is_dict)
    activation = _activation(path, algo, kwargs, kwargs_globals)
    use_sde = _flag(path, data, "use_sde")
    if "use_sde" in kwargs and _flag(path, kwargs, "use_sde") != use_sde:
        _fail(path, "use_sde in the data and in policy_kwargs disagree")

    state = _load_state_dict(path, policy_bytes)
    clip_mean: float | None = None
    if algo == "PPO":
        squash = _flag(path, kwargs, "squash_output")
        if squash and not use_sde:
            _fail(path, "PPO with squash_output but without use_sde is not an SB3 configuration")
        hidden, output = _ppo_actor(path, state)
    elif algo == "SAC":
        squash = True
        if use_sde:
            clip_mean = _number(path, kwargs.get("clip_mean", 2.0), "clip_mean")
            clip_mean = clip_mean if clip_mean > 0.0 else None
        hidden, output = _sac_actor(path, state, clip_mean is not None)
    else:
        squash = True
        if use_sde:
            _fail(path, "TD3 with use_sde is not an SB3 configuration")
        hidden, output = _td3_actor(path, state)

    in_width = (hidden[0] if hidden else output)[0].shape[1]
    obs_dim = sum(width for _, width in obs_parts)
    if in_width != obs_dim:
        _fail(path, f"the actor's first layer takes {in_width} inputs but the observation space has {obs_dim}")
    if output[0].shape[0] != low.shape[0]:
        _fail(path, f"the actor outputs {output[0].shape[0]} actions but the action space has {low.shape[0]}")
    _check_net_arch(path, algo, kwargs, [w.shape[0] for w, _ in hidden])
    if squash and not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        _fail(path, f"{algo} squashes its actions into [low, high] but the action bounds are not finite")
    for array in (low, high, *(a for layer in (*hidden, output) for a in layer)):
        array.setflags(write=False)
    return SB3Policy(
        algo=algo,
        obs_parts=obs_parts,
        obs_is_dict=obs_is_dict,
        action_low=low,
        action_high=high,
        _hidden=tuple(hidden),
        _output=output,
        _activation=activation,
        _squash=squash,
        _clip_mean=clip_mean,
    )


# ----------------------------------------------------------------------------------------------------------------------
# Reading the file


def _fail(path: Path, problem: str) -> NoReturn:
    raise ValueError(f"{path}: {' '.join(problem.split())}")


def _read_members(path: Path) -> tuple[bytes, bytes]:
    """The ``data`` and ``policy.pth`` members, each checked against :data:`MAX_MEMBER_BYTES` before it is read."""
    if not path.is_file():
        _fail(path, "no such file")
    try:
        with zipfile.ZipFile(path) as archive:
            infos = archive.infolist()
            found: dict[str, zipfile.ZipInfo] = {}
            for name in ("data", "policy.pth"):
                matches = [info for info in infos if info.filename == name]
                if not matches:
                    _fail(path, f"not an SB3 save file (the zip has no {name!r})")
                if len(matches) > 1:
                    _fail(path, f"the zip holds {name!r} more than once")
                if matches[0].file_size > MAX_MEMBER_BYTES:
                    _fail(path, f"{name!r} is {matches[0].file_size} bytes uncompressed, over the {MAX_MEMBER_BYTES} limit")
                found[name] = matches[0]
            contents = []
            for name in ("data", "policy.pth"):
                with archive.open(found[name]) as member:
                    raw = member.read(MAX_MEMBER_BYTES + 1)
                if len(raw) > MAX_MEMBER_BYTES:
                    _fail(path, f"{name!r} is over the {MAX_MEMBER_BYTES} bytes limit")
                contents.append(raw)
    except (
        zipfile.BadZipFile,
        zipfile.LargeZipFile,
        zlib.error,
        OSError,
        EOFError,
        NotImplementedError,
        RuntimeError,
    ) as error:
        _fail(path, f"not a readable zip file ({type(error).__name__})")
    return contents[0], contents[1]


def _pickle_globals(blob: Any) -> list[tuple[str, str]] | None:
    """The ``(module, name)`` globals a base64 pickle refers to, found by disassembling it (nothing is executed).

    None where the blob is not base64 or its opcodes do not parse. Strings are followed through the memo so that a
    module name pickled once and reused still counts.
    """
    if not isinstance(blob, str):
        return None
    try:
        raw = base64.b64decode(blob, validate=True)
    except (binascii.Error, ValueError):
        return None
    found: list[tuple[str, str]] = []
    memo: dict[int, Any] = {}
    recent: list[Any] = []  # values pushed by the last ops (strings, or None for anything else)
    try:
        for opcode, arg, _ in pickletools.genops(raw):
            name = opcode.name
            if name in {"SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8", "UNICODE", "SHORT_BINSTRING", "BINSTRING"}:
                recent.append(arg if isinstance(arg, str) else None)
            elif name == "MEMOIZE":
                memo[len(memo)] = recent[-1] if recent else None
            elif name in {"PUT", "BINPUT", "LONG_BINPUT"}:
                memo[int(arg)] = recent[-1] if recent else None
            elif name in {"GET", "BINGET", "LONG_BINGET"}:
                recent.append(memo.get(int(arg)))
            elif name == "STACK_GLOBAL":
                if len(recent) >= 2 and isinstance(recent[-2], str) and isinstance(recent[-1], str):
                    found.append((recent[-2], recent[-1]))
                recent.append(None)
            elif name in {"GLOBAL", "INST"} and isinstance(arg, str) and " " in arg:
                module, _, qualname = arg.partition(" ")
                found.append((module, qualname))
                recent.append(None)
            elif name not in {"FRAME", "PROTO"}:
                recent.append(None)
            del recent[:-2]
    except (ValueError, TypeError, IndexError, KeyError, EOFError):
        return None
    return found


def _identify_algo(path: Path, data: Mapping[str, Any]) -> tuple[str, bool]:
    """The algorithm ("PPO", "SAC", "TD3") and whether its policy takes a Dict observation, from readable evidence."""
    policy_class = data.get("policy_class")
    if not isinstance(policy_class, dict):
        _fail(path, "not an SB3 save file ('data' has no policy_class)")
    found = _pickle_globals(policy_class.get(":serialized:"))
    if found is None or len(found) != 1:
        module = policy_class.get("__module__")
        _fail(
            path,
            f"the policy class (module {module!r}) is not a class of SB3's PPO, SAC or TD3 that can be read without "
            f"unpickling (a custom policy?); supported: {_SUPPORTED}",
        )
    module, name = found[0]
    readable_module = policy_class.get("__module__")
    if readable_module is not None and readable_module != module:
        _fail(path, f"the policy class's module reads {readable_module!r} and {module!r}")
    if (module, name) not in _POLICY_CLASSES:
        parts = module.split(".")
        guess = parts[1].upper() if len(parts) == 3 and parts[2] == "policies" and parts[1] != "common" else None
        if "Cnn" in name:
            _fail(
                path,
                f"unsupported policy class {module}.{name}: a CNN (image) policy; supported: the MlpPolicy and "
                f"MultiInputPolicy of {_SUPPORTED}",
            )
        what = f"a {guess} policy" if guess else "not a policy of PPO, SAC or TD3"
        _fail(path, f"unsupported algorithm: policy class {module}.{name} is {what}; supported: {_SUPPORTED}")
    family, dict_policy = _POLICY_CLASSES[(module, name)]
    if family == "PPO" and not {"clip_range", "n_epochs"} <= set(data):
        _fail(
            path,
            f"unsupported algorithm: an actor-critic policy ({name}) saved without PPO's clip_range and n_epochs "
            f"(A2C or another on-policy algorithm); supported: {_SUPPORTED}",
        )
    if family == "SAC" and not {"ent_coef", "target_entropy"} <= set(data):
        _fail(
            path,
            f"unsupported algorithm: a SAC policy saved without SAC's ent_coef and target_entropy; supported: {_SUPPORTED}",
        )
    if family == "TD3":
        if not {"policy_delay", "target_noise_clip", "target_policy_noise"} <= set(data):
            _fail(path, f"unsupported algorithm: a TD3 policy saved without TD3's policy_delay; supported: {_SUPPORTED}")
        if (data["policy_delay"], data["target_noise_clip"], data["target_policy_noise"]) == (1, 0.0, 0.1):
            _fail(path, f"unsupported algorithm: DDPG (TD3's policy with DDPG's fixed settings); supported: {_SUPPORTED}")
    return family, dict_policy


_BOX_TYPES = {"<class 'gymnasium.spaces.box.Box'>", "<class 'gym.spaces.box.Box'>"}
_DICT_TYPES = {"<class 'gymnasium.spaces.dict.Dict'>", "<class 'gym.spaces.dict.Dict'>"}
_DICT_KEY = re.compile(r"""(?:'((?:[^'\\])*)'|"((?:[^"\\])*)"): ([A-Za-z_]\w*)\(""")
_DICT_BOX = re.compile(r"""(?:'((?:[^'\\])*)'|"((?:[^"\\])*)"): Box\([^()]*?, \(([0-9, ]*)\), (\w+)\)""", re.DOTALL)


def _space_type(space: Any) -> str:
    return str(space.get(":type:")) if isinstance(space, dict) else type(space).__name__


def _box_shape(path: Path, space: Mapping[str, Any], what: str) -> tuple[tuple[int, ...], str]:
    shape, dtype = space.get("_shape"), space.get("dtype")
    if not isinstance(shape, list) or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
        _fail(path, f"the {what} has no readable shape")
    if not isinstance(dtype, str):
        _fail(path, f"the {what} has no readable dtype")
    return tuple(shape), dtype


def _observation_parts(path: Path, space: Any) -> tuple[tuple[tuple[str, int], ...], bool]:
    kind = _space_type(space)
    if kind in _BOX_TYPES:
        shape, dtype = _box_shape(path, space, "observation space")
        if len(shape) == 3 and dtype == "uint8":
            _fail(path, f"unsupported observation space: an image-like uint8 Box {shape} (SB3 may divide it by 255)")
        return (("observation", math.prod(shape)),), False
    if kind in _DICT_TYPES:
        text = space.get("spaces")
        if not isinstance(text, str):
            _fail(path, "unsupported observation space: a Dict whose sub-spaces are not readable")
        entries = [(a or b, sub) for a, b, sub in _DICT_KEY.findall(text)]
        others = sorted({sub for _, sub in entries if sub != "Box"})
        if others:
            _fail(path, f"unsupported observation space: a Dict holding {', '.join(others)} (only Box sub-spaces)")
        boxes = [(a or b, shape, dtype) for a, b, shape, dtype in _DICT_BOX.findall(text)]
        if not boxes or [key for key, _, _ in boxes] != [key for key, _ in entries]:
            _fail(path, "unsupported observation space: a Dict whose sub-spaces could not be read")
        parts = []
        for key, shape_text, _dtype in boxes:
            shape = tuple(int(n) for n in shape_text.replace(" ", "").split(",") if n)
            if len(shape) == 3:
                _fail(path, f"unsupported observation space: Dict key {key!r} is image-like {shape} (SB3 would use a CNN)")
            parts.append((key, math.prod(shape)))
        return tuple(parts), True
    _fail(path, f"unsupported observation space {kind} (only Box and Dict of Box)")


def _parse_array(text: Any) -> list[float] | None:
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        return [float(text)]
    if not isinstance(text, str) or "..." in text:
        return None
    try:
        return [float(token) for token in text.replace("[", " ").replace("]", " ").split()]
    except ValueError:
        return None


def _action_bounds(path: Path, space: Any) -> tuple[np.ndarray, np.ndarray]:
    kind = _space_type(space)
    if kind not in _BOX_TYPES:
        _fail(path, f"unsupported action space {kind} (only Box)")
    shape, dtype = _box_shape(path, space, "action space")
    if len(shape) != 1 or shape[0] < 1:
        _fail(path, f"unsupported action space: a Box of shape {shape} (only one-dimensional)")
    try:
        stored = np.dtype(dtype)
    except TypeError:
        _fail(path, f"the action space's dtype {dtype!r} is not readable")
    if stored.kind != "f":
        _fail(path, f"unsupported action space: a {dtype} Box (only floating point)")
    bounds = []
    for name in ("low", "high"):
        values = _parse_array(space.get(name))
        if values is None or len(values) != shape[0]:
            _fail(path, f"the action space's {name} is not readable as {shape[0]} numbers")
        # The text is numpy's shortest repr of the stored values: round back to the stored dtype to get them exactly.
        bounds.append(np.asarray(values, dtype=np.float64).astype(stored).astype(np.float64))
    low, high = bounds
    if np.any(np.isnan(low)) or np.any(np.isnan(high)) or np.any(low > high):
        _fail(path, "the action space's bounds are not ordered numbers")
    return low, high


def _policy_kwargs(path: Path, kwargs: Any) -> tuple[dict[str, Any], list[tuple[str, str]]]:
    """The readable policy_kwargs (values not JSON are SB3's ``str()`` of them) and the globals the blob names."""
    if kwargs is None:
        return {}, []
    if not isinstance(kwargs, dict):
        _fail(path, "policy_kwargs is not readable")
    readable = {key: value for key, value in kwargs.items() if not key.startswith(":")}
    if ":serialized:" not in kwargs:
        return readable, []
    found = _pickle_globals(kwargs[":serialized:"])
    if found is None:
        _fail(path, "policy_kwargs' serialized part does not parse")
    return readable, found


def _class_repr(value: Any) -> tuple[str, str] | None:
    match = re.fullmatch(r"<class '([\w.]+)\.(\w+)'>", value) if isinstance(value, str) else None
    return (match.group(1), match.group(2)) if match else None


def _check_extractor(path: Path, kwargs: Mapping[str, Any], found: list[tuple[str, str]], obs_is_dict: bool) -> None:
    expected = "CombinedExtractor" if obs_is_dict else "FlattenExtractor"
    if "features_extractor_class" in kwargs:
        cls = _class_repr(kwargs["features_extractor_class"])
        if cls != (_TORCH_LAYERS, expected) or cls not in found:
            _fail(path, f"unsupported features_extractor_class {kwargs['features_extractor_class']} (only SB3's {expected})")
    extractor_kwargs = kwargs.get("features_extractor_kwargs") or {}
    allowed = {"cnn_output_dim", "normalized_image"} if obs_is_dict else set()
    if not isinstance(extractor_kwargs, dict) or set(extractor_kwargs) - allowed:
        _fail(path, f"unsupported features_extractor_kwargs {extractor_kwargs}")


def _activation(path: Path, algo: str, kwargs: Mapping[str, Any], found: list[tuple[str, str]]) -> str:
    """The activation's class name: the torch.nn.modules.activation global in the serialized policy_kwargs.

    The readable ``str()`` SB3 writes beside it, where present, must name the same class.
    """
    if "activation_fn" not in kwargs:
        return _DEFAULT_ACTIVATION[algo]
    names = {name for module, name in found if module == _ACTIVATION_MODULE}
    readable = _class_repr(kwargs["activation_fn"])
    if readable is not None:
        names.add(readable[1] if readable[0] == _ACTIVATION_MODULE else f"{readable[0]}.{readable[1]}")
    if len(names) != 1 or next(iter(names)) not in _ACTIVATIONS:
        _fail(
            path,
            f"unsupported activation_fn {kwargs['activation_fn']} (only torch.nn {', '.join(_ACTIVATIONS)}, "
            "read from the saved class name)",
        )
    return next(iter(names))


def _flag(path: Path, mapping: Mapping[str, Any], key: str) -> bool:
    value = mapping.get(key, False)
    if not isinstance(value, bool):
        _fail(path, f"{key} is not a readable boolean")
    return value


def _number(path: Path, value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _fail(path, f"{key} is not a readable finite number")
    return float(value)


def _check_net_arch(path: Path, algo: str, kwargs: Mapping[str, Any], widths: list[int]) -> None:
    """Where ``net_arch`` is readable, the hidden widths found in policy.pth must be the actor's part of it."""
    arch = kwargs.get("net_arch")
    if algo == "PPO" and isinstance(arch, list) and arch and isinstance(arch[0], dict):
        arch = arch[0]  # SB3 < 1.8's [dict(pi=..., vf=...)], still accepted with a warning
    if isinstance(arch, dict):
        arch = arch.get("pi")
    if isinstance(arch, list) and all(isinstance(n, int) for n in arch) and list(arch) != widths:
        _fail(path, f"net_arch {list(arch)} does not match the actor's hidden widths {widths} in policy.pth")


def _load_state_dict(path: Path, raw: bytes) -> dict[str, np.ndarray]:
    import torch

    try:
        state = torch.load(io.BytesIO(raw), weights_only=True, map_location="cpu")
    except Exception as error:  # any refusal of the weights-only loader is the file's problem
        _fail(
            path,
            f"policy.pth is not a plain tensor state dict (torch's weights-only loader refused it: {type(error).__name__})",
        )
    if not isinstance(state, Mapping):
        _fail(path, "policy.pth does not hold a state dict")
    arrays: dict[str, np.ndarray] = {}
    for key, value in state.items():
        if not isinstance(key, str) or not isinstance(value, torch.Tensor):
            _fail(path, f"policy.pth entry {key!r} is not a named tensor")
        if not value.is_floating_point():
            _fail(path, f"policy.pth tensor {key!r} is {value.dtype}, not floating point")
        arrays[key] = value.detach().to(device="cpu", dtype=torch.float64).numpy().copy()
    return arrays


def _linear(path: Path, state: Mapping[str, np.ndarray], prefix: str, in_width: int | None) -> _Layer:
    weight, bias = state.get(f"{prefix}weight"), state.get(f"{prefix}bias")
    if weight is None or bias is None:
        _fail(path, f"policy.pth lacks {prefix}weight or {prefix}bias")
    if weight.ndim != 2 or bias.shape != (weight.shape[0],) or (in_width is not None and weight.shape[1] != in_width):
        expected = f"[*, {in_width}]" if in_width is not None else "[out, in]"
        _fail(
            path,
            f"policy.pth tensor shapes do not match the layout: {prefix}weight {list(weight.shape)} (expected {expected}), "
            f"{prefix}bias {list(bias.shape)}",
        )
    if not (np.all(np.isfinite(weight)) and np.all(np.isfinite(bias))):
        _fail(path, f"policy.pth {prefix}weight or bias holds non-finite values")
    return weight, bias


def _sequential(path: Path, state: Mapping[str, np.ndarray], prefix: str) -> list[_Layer]:
    """The Linear layers of an SB3 MLP ``nn.Sequential`` (Linear, activation, Linear, ...) at indices 0, 2, 4, ..."""
    pattern = re.compile(re.escape(prefix) + r"(\d+)\.(weight|bias)")
    indices = set()
    for key in state:
        match = pattern.fullmatch(key)
        if match:
            indices.add(int(match.group(1)))
        elif key.startswith(prefix):
            _fail(path, f"unexpected tensor {key!r} in policy.pth (a layer SB3's MLP does not have)")
    if sorted(indices) != list(range(0, 2 * len(indices), 2)):
        _fail(
            path, f"the layers under {prefix!r} in policy.pth are not at SB3's MLP positions 0, 2, 4, ...: {sorted(indices)}"
        )
    layers: list[_Layer] = []
    for index in sorted(indices):
        layers.append(_linear(path, state, f"{prefix}{index}.", layers[-1][0].shape[0] if layers else None))
    return layers


def _unexpected(path: Path, keys: list[str], algo: str) -> None:
    if keys:
        shown = ", ".join(repr(key) for key in sorted(keys)[:4]) + (", ..." if len(keys) > 4 else "")
        _fail(path, f"unexpected tensors in policy.pth for an {algo} MLP actor ({shown}): a custom or CNN feature extractor?")


def _ppo_actor(path: Path, state: Mapping[str, np.ndarray]) -> tuple[list[_Layer], _Layer]:
    if "action_net.weight" not in state or "log_std" not in state:
        _fail(path, "policy.pth lacks PPO's action_net and log_std")
    hidden = _sequential(path, state, "mlp_extractor.policy_net.")
    output = _linear(path, state, "action_net.", hidden[-1][0].shape[0] if hidden else None)
    known = ("mlp_extractor.policy_net.", "mlp_extractor.value_net.", "value_net.", "action_net.")
    _unexpected(path, [key for key in state if key != "log_std" and not key.startswith(known)], "PPO")
    return hidden, output


def _sac_actor(path: Path, state: Mapping[str, np.ndarray], clipped_mean: bool) -> tuple[list[_Layer], _Layer]:
    if not any(key.startswith("actor.latent_pi.") or key.startswith("actor.mu.") for key in state):
        _fail(path, "policy.pth lacks SAC's actor.latent_pi and actor.mu")
    hidden = _sequential(path, state, "actor.latent_pi.")
    mu = "actor.mu.0." if clipped_mean else "actor.mu."
    output = _linear(path, state, mu, hidden[-1][0].shape[0] if hidden else None)
    actor_known = {f"{mu}weight", f"{mu}bias", "actor.log_std", "actor.log_std.weight", "actor.log_std.bias"}
    keys = [
        key
        for key in state
        if not key.startswith(("actor.latent_pi.", "critic.", "critic_target.")) and key not in actor_known
    ]
    _unexpected(path, keys, "SAC")
    return hidden, output


def _td3_actor(path: Path, state: Mapping[str, np.ndarray]) -> tuple[list[_Layer], _Layer]:
    if "actor.mu.0.weight" not in state:
        _fail(path, "policy.pth lacks TD3's actor.mu")
    layers = _sequential(path, state, "actor.mu.")
    keys = [key for key in state if not key.startswith(("actor.mu.", "actor_target.", "critic.", "critic_target."))]
    _unexpected(path, keys, "TD3")
    return layers[:-1], layers[-1]
