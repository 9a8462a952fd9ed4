"""Checkpoints on disk: tensors in safetensors, everything else in JSON, never pickle.

A checkpoint is a directory holding two files:

* ``weights.safetensors`` -- every tensor (contiguous, CPU), parsed only by the safetensors reader, so a file from
  someone else can never run code on load (``torch.load`` and ``pickle`` are never called);
* ``meta.json`` -- ``{"format": FORMAT_VERSION, "sha256": <hex digest of weights.safetensors>, "tensors": [<sorted
  names>], "meta": <the caller's JSON dict>}``.

Saving is atomic for a single writer. The new checkpoint is built in a hidden sibling ``.NAME.tmp-XXXX/`` (same parent,
so the renames below stay on one file system), each file and the directory are fsynced, then

1. an existing ``NAME/`` is renamed to ``.NAME.old-XXXX/``,
2. ``.NAME.tmp-XXXX/`` is renamed to ``NAME/`` and the parent directory is fsynced,
3. ``.NAME.old-XXXX/`` is deleted.

A process killed at any moment therefore leaves a complete ``NAME/`` (old or new), or -- killed between steps 1 and 2 --
no ``NAME/`` but a complete ``.NAME.old-XXXX/``. Readers handle that state without writing anything:
:func:`resolve_checkpoint` points them at the ``.old`` copy, and :func:`checkpoint_exists` -- what every entry point
asks before it decides between a fresh run and a resumed one -- counts it as a checkpoint. The next
:func:`save_checkpoint` repairs it (renames the ``.old`` copy back) and deletes leftover ``.tmp``/``.old`` siblings
before it writes. That repair, like the whole save, runs under the parent directory's lock
(:func:`hrlp.atomic.directory_lock`, which a training run holds for its whole length), so a writer never deletes the
temporary directory of another writer's save in progress: a second writer fails at once with a one-line error
instead. Readers never modify the file system, so an evaluator may load while a trainer saves; both files are opened
through one directory handle, so a reader never pairs the weights of one checkpoint with the metadata of another.

A file system error while saving (full disk, read-only directory) raises :class:`hrlp.atomic.StorageError` (one line
naming the checkpoint); the previous checkpoint stays as it was.

What the content hash covers: ``sha256`` in ``meta.json`` is the digest of the bytes of ``weights.safetensors``, and of
nothing else. It detects a truncated, damaged or swapped weights file, and it is a skill's identity (its
``content_hash``, recorded by every Manager trained with it and by DAgger's lineage), so it must not change when only
the JSON beside it does. ``meta.json`` is not hashed: a digest stored in the file it covers detects nothing that an
editor could not recompute, and a truncated JSON file already fails to parse. Instead, every reader checks the keys it
needs (``required`` in :func:`load_checkpoint`: a missing or mistyped key is a one-line :class:`CheckpointError` naming
the file, never a ``KeyError``), and the list of tensor names in ``meta.json`` must match the weights exactly.

Reading is bounded, because a checkpoint may come from someone else: both files are opened without following a
symbolic link and without blocking (``O_NOFOLLOW | O_NONBLOCK``), must be regular files (a FIFO, a device such as
``/dev/zero`` or a directory is refused before a byte is read), and may not exceed the sizes of :class:`ReadLimits`;
JSON nested deeper than its ``max_json_depth``, or holding NaN, Infinity or an out-of-range number, is refused before it
is parsed. A caller that builds something from the tensors' shapes (:mod:`hrlp.skills.library`) can check the
safetensors header (:func:`safetensors_header`) against the meta through ``before_tensors``, before any tensor exists.

Random-number generators are stored through :func:`pack_generators` / :func:`unpack_generators` (numpy bit-generator
states in JSON, torch generator states as uint8 tensors), and modules through :func:`module_tensors` /
:func:`load_module`::

    tensors = {**module_tensors("policy", policy), **rng_tensors}
    save_checkpoint(run_dir / "checkpoint", tensors, {"iteration": i, **rng_meta})
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import re
import secrets
import shutil
import stat
import struct
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import safetensors.torch
import torch
from safetensors import SafetensorError

from hrlp.atomic import StorageError, directory_lock
from hrlp.config import TrainConfig

FORMAT_VERSION = 1
WEIGHTS_FILE = "weights.safetensors"
META_FILE = "meta.json"
_RNG_KEY = "rng"
# Opening never blocks (a FIFO), never follows a symbolic link to a file, and never leaks into child processes;
# getattr: flags a platform lacks (Windows) are left out.
_NO_WAIT = getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
_OPEN_DIR = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | _NO_WAIT
_OPEN_FILE = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | _NO_WAIT
_TORCH_RNG_PREFIX = "rng.torch."


class CheckpointError(ValueError):
    """A checkpoint is missing, incomplete, modified, or does not match what the caller expects."""


@dataclass(frozen=True)
class ReadLimits:
    """Bounds on what :func:`load_checkpoint` reads: larger or deeper files are refused before they are parsed."""

    max_meta_bytes: int = 64 * 2**20
    """Largest ``meta.json`` (a training run's holds its sampler state: about 5 KB per environment)."""
    max_weights_bytes: int = 4 * 2**30
    """Largest ``weights.safetensors``."""
    max_json_depth: int = 64
    """Deepest nesting of arrays and objects in ``meta.json`` (a training run's: 7); Python's parser would otherwise
    raise RecursionError on a deep enough file."""


#: Limits for any checkpoint (training runs); skills use tighter ones (:mod:`hrlp.skills.library`).
DEFAULT_LIMITS = ReadLimits()


class TensorInfo(NamedTuple):
    """What the safetensors header says about one tensor, read before the tensor is built."""

    dtype: str
    """The safetensors dtype code, e.g. ``F32``, ``F64``, ``I64``."""
    shape: tuple[int, ...]
    """The tensor's shape."""


# --- saving ---------------------------------------------------------------------------------------------------------


def save_checkpoint(directory: Path, tensors: Mapping[str, torch.Tensor], meta: Mapping[str, Any]) -> Path:
    """Atomically write ``tensors`` and the JSON-serialisable ``meta`` to the checkpoint ``directory``; returns it.

    ``directory`` is replaced as a whole (see the module docstring for the protocol). An existing ``directory``
    must be a checkpoint (only ``weights.safetensors`` and ``meta.json``) or empty, so a mistyped path never deletes
    someone's files. Tensors are detached, copied to contiguous CPU memory (tied weights become separate copies).
    Raises ``TypeError`` for a non-tensor value, ``ValueError`` for meta that is not strict JSON, both before
    anything is written; :class:`hrlp.atomic.DirectoryLockedError` if another process holds the lock of the parent
    directory; :class:`hrlp.atomic.StorageError` (one line naming ``directory``) if the file system refuses the write,
    leaving the previous checkpoint as it was.
    """
    directory = Path(directory)
    weights_bytes = _serialise_tensors(tensors)
    meta_bytes = _serialise_meta(weights_bytes, sorted(tensors), meta)
    with directory_lock(directory.parent, "directory"):
        had_previous = checkpoint_exists(directory)
        note = "the previous checkpoint is unchanged" if had_previous else ""
        try:
            return _save_locked(directory, weights_bytes, meta_bytes)
        except StorageError as error:
            raise StorageError(directory, error, note) from error
        except OSError as error:
            raise StorageError(directory, error, note) from error


def _save_locked(directory: Path, weights_bytes: bytes, meta_bytes: bytes) -> Path:
    """The save protocol (module docstring), run under the parent directory's lock."""
    parent = directory.parent
    _recover(directory)
    _check_replaceable(directory)

    tmp = Path(tempfile.mkdtemp(prefix=f".{directory.name}.tmp-", dir=parent))
    old: Path | None = None
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp creates 0700; give the directory the usual permissions
        _write_synced(tmp / WEIGHTS_FILE, weights_bytes)
        _write_synced(tmp / META_FILE, meta_bytes)
        _fsync_directory(tmp)
        if directory.exists():
            old = parent / f".{directory.name}.old-{secrets.token_hex(4)}"
            os.replace(directory, old)
        os.replace(tmp, directory)
        _fsync_directory(parent)
    except BaseException:
        if old is not None and not directory.exists():
            os.replace(old, directory)
            old = None
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return directory


def _serialise_tensors(tensors: Mapping[str, torch.Tensor]) -> bytes:
    prepared: dict[str, torch.Tensor] = {}
    for name, tensor in tensors.items():
        if not isinstance(name, str):
            raise TypeError(f"tensor names must be str, got {name!r}")
        if not isinstance(tensor, torch.Tensor):
            raise TypeError(f"{name!r} is a {type(tensor).__name__}, not a torch.Tensor")
        # clone: safetensors refuses tensors that share storage (tied weights, views of one buffer)
        prepared[name] = tensor.detach().to("cpu").contiguous().clone()
    return safetensors.torch.save(prepared)


def _serialise_meta(weights_bytes: bytes, names: list[str], meta: Mapping[str, Any]) -> bytes:
    document = {"format": FORMAT_VERSION, "sha256": hashlib.sha256(weights_bytes).hexdigest(), "tensors": names}
    document["meta"] = dict(meta)
    try:
        # allow_nan=False: NaN/Infinity are not JSON and other readers reject them
        text = json.dumps(document, indent=2, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as error:
        raise ValueError(f"checkpoint meta is not strict JSON: {error}") from error
    return (text + "\n").encode("utf-8")


def _write_synced(path: Path, data: bytes) -> None:
    with open(path, "wb") as file:
        file.write(data)
        file.flush()
        os.fsync(file.fileno())


def _fsync_directory(path: Path) -> None:
    """Make a directory's entries (new files, renames) durable; a no-op where directories cannot be opened."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # Windows cannot open directories
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _siblings(directory: Path, kind: str) -> list[Path]:
    return sorted(directory.parent.glob(f".{directory.name}.{kind}-*"))


def _recover(directory: Path) -> None:
    """Writer-side repair: restore an ``.old`` copy left by a kill between the renames, then drop leftovers."""
    if not directory.exists():
        with contextlib.suppress(CheckpointError):
            os.replace(resolve_checkpoint(directory), directory)
            _fsync_directory(directory.parent)
    for leftover in _siblings(directory, "tmp") + _siblings(directory, "old"):
        shutil.rmtree(leftover, ignore_errors=True)


def _check_replaceable(directory: Path) -> None:
    if not directory.exists():
        return
    if not directory.is_dir():
        raise CheckpointError(f"{directory}: exists and is not a directory; refusing to replace it")
    foreign = sorted(p.name for p in directory.iterdir() if p.name not in (WEIGHTS_FILE, META_FILE))
    if foreign:
        raise CheckpointError(f"{directory}: not a checkpoint (contains {', '.join(foreign)}); refusing to replace it")


# --- loading --------------------------------------------------------------------------------------------------------


def checkpoint_exists(directory: Path) -> bool:
    """Whether ``directory`` holds a checkpoint to continue from: ``directory`` itself, or the complete ``.old`` copy
    a save killed between its two renames leaves (exactly what :func:`resolve_checkpoint` and :func:`load_checkpoint`
    read). Every entry point that chooses between a fresh run and a resumed one asks this, so none of them mistakes
    that state for an empty directory."""
    try:
        resolve_checkpoint(directory)
    except CheckpointError:
        return Path(directory).exists()  # something is there (not a checkpoint): never treat it as empty
    return True


def resolve_checkpoint(directory: Path) -> Path:
    """The directory to read the checkpoint ``directory`` from, without modifying anything.

    That is ``directory`` itself, or -- if a save was killed between its two renames -- the complete
    ``.NAME.old-XXXX`` sibling holding the previous checkpoint. Raises :class:`CheckpointError` if neither exists.
    """
    directory = Path(directory)
    if directory.is_dir():
        return directory
    complete = [p for p in _siblings(directory, "old") if (p / META_FILE).is_file() and (p / WEIGHTS_FILE).is_file()]
    if not complete:
        raise CheckpointError(f"{directory}: no checkpoint (directory missing)")
    return max(complete, key=lambda p: p.stat().st_mtime_ns)


class Checkpoint(NamedTuple):
    """A checkpoint as read by :func:`read_checkpoint`."""

    tensors: dict[str, torch.Tensor]
    """Every tensor, by name."""
    meta: dict[str, Any]
    """The caller's JSON dict."""
    sha256: str
    """Hex digest of ``weights.safetensors`` (verified): the checkpoint's content hash."""


def load_checkpoint(
    directory: Path,
    *,
    required: Mapping[str, type | tuple[type, ...]] | None = None,
    limits: ReadLimits = DEFAULT_LIMITS,
    before_tensors: Callable[[dict[str, Any], dict[str, TensorInfo]], None] | None = None,
) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """``(tensors, meta)`` of the checkpoint in ``directory``: :func:`read_checkpoint` without the hash."""
    tensors, meta, _ = read_checkpoint(directory, required=required, limits=limits, before_tensors=before_tensors)
    return tensors, meta


def read_checkpoint(
    directory: Path,
    *,
    required: Mapping[str, type | tuple[type, ...]] | None = None,
    limits: ReadLimits = DEFAULT_LIMITS,
    before_tensors: Callable[[dict[str, Any], dict[str, TensorInfo]], None] | None = None,
) -> Checkpoint:
    """Read and verify a checkpoint written by :func:`save_checkpoint`.

    Verifies the format version, the sha256 of ``weights.safetensors`` and the tensor names; ``required`` maps keys the
    caller's meta must hold to their JSON types (``int`` excludes ``bool``). Any problem -- a missing file, a file that
    is a symbolic link, not a regular file or larger than ``limits``, a truncated or modified file, invalid or too deeply
    nested JSON, an unknown format, a missing or mistyped required key -- raises :class:`CheckpointError` with a
    one-line message naming the file. ``before_tensors(meta, header)``, if given, is called with the safetensors header
    once the files are verified and before any tensor is built, so it can refuse shapes and dtypes first. The weights
    are parsed by safetensors only (no pickle, no ``torch.load``); the bytes parsed are exactly the bytes hashed.
    """
    source = resolve_checkpoint(directory)
    meta_path, weights_path = source / META_FILE, source / WEIGHTS_FILE
    try:
        dir_fd = os.open(source, _OPEN_DIR)
    except OSError as error:
        raise CheckpointError(f"{source}: cannot open ({error.strerror})") from error
    try:
        meta_bytes = _read_at(dir_fd, META_FILE, meta_path, limits.max_meta_bytes)
        weights_bytes = _read_at(dir_fd, WEIGHTS_FILE, weights_path, limits.max_weights_bytes)
    finally:
        os.close(dir_fd)

    document = _parse_meta(meta_bytes, meta_path, limits.max_json_depth)
    if required:
        require_keys(document["meta"], required, meta_path)
    digest = hashlib.sha256(weights_bytes).hexdigest()
    if digest != document["sha256"]:
        raise CheckpointError(
            f"{weights_path}: sha256 {digest[:12]}... does not match {document['sha256'][:12]}... in {META_FILE}"
            " (file truncated or modified)"
        )
    if before_tensors is not None:
        header = safetensors_header(weights_bytes, weights_path, limits.max_json_depth)
        if sorted(header) == document["tensors"]:  # otherwise the check of the names below says what differs
            before_tensors(document["meta"], header)
    try:
        tensors = safetensors.torch.load(weights_bytes)
    except (SafetensorError, ValueError, RuntimeError) as error:
        raise CheckpointError(f"{weights_path}: not a valid safetensors file ({_one_line(error)})") from error
    if sorted(tensors) != document["tensors"]:
        missing = sorted(set(document["tensors"]) - set(tensors))
        unexpected = sorted(set(tensors) - set(document["tensors"]))
        raise CheckpointError(
            f"{weights_path}: tensor names differ from {META_FILE} (missing {missing}, unexpected {unexpected})"
        )
    return Checkpoint(tensors, document["meta"], digest)


def require_keys(meta: Mapping[str, Any], required: Mapping[str, type | tuple[type, ...]], path: Path) -> None:
    """Raise :class:`CheckpointError` naming ``path`` unless ``meta`` holds every key of ``required`` with a value of
    its type (``int`` and ``float`` exclude ``bool``; ``float`` accepts an ``int``)."""
    for key, kinds in required.items():
        if key not in meta:
            raise CheckpointError(f"{path}: no {key!r} in its meta (needed: {', '.join(required)})")
        if not _is_json_type(meta[key], kinds):
            names = " or ".join(k.__name__ for k in (kinds if isinstance(kinds, tuple) else (kinds,)))
            raise CheckpointError(f"{path}: {key!r} must be {names}, got {type(meta[key]).__name__} {_short(meta[key])}")


def _is_json_type(value: Any, kinds: type | tuple[type, ...]) -> bool:
    for kind in kinds if isinstance(kinds, tuple) else (kinds,):
        if kind in (int, float) and isinstance(value, bool):
            continue
        if isinstance(value, kind) or (kind is float and isinstance(value, int) and not isinstance(value, bool)):
            return True
    return False


def _short(value: Any, width: int = 40) -> str:
    text = repr(value).replace("\n", " ")
    return text if len(text) <= width else text[: width - 3] + "..."


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split())


def safetensors_header(weights: bytes, path: Path, max_json_depth: int = 64) -> dict[str, TensorInfo]:
    """The dtype and shape of every tensor in a safetensors file's bytes, from its header alone (8 bytes of header
    length, then a JSON object); no tensor is built. Raises :class:`CheckpointError` naming ``path``."""
    if len(weights) < 8:
        raise CheckpointError(f"{path}: not a valid safetensors file ({len(weights)} bytes, no header)")
    (size,) = struct.unpack("<Q", weights[:8])
    if size > len(weights) - 8:
        raise CheckpointError(f"{path}: not a valid safetensors file (header of {size} bytes in a file of {len(weights)})")
    header = parse_json(weights[8 : 8 + size], path, max_json_depth, what="safetensors header")
    if not isinstance(header, dict):
        raise CheckpointError(f"{path}: not a valid safetensors file (header is not a JSON object)")
    out: dict[str, TensorInfo] = {}
    for name, entry in header.items():
        if name == "__metadata__":
            continue
        dtype, shape = (entry.get("dtype"), entry.get("shape")) if isinstance(entry, dict) else (None, None)
        sizes = shape if isinstance(shape, list) else [-1]
        if not isinstance(dtype, str) or not all(_is_json_type(n, int) and n >= 0 for n in sizes):
            raise CheckpointError(f"{path}: not a valid safetensors file (tensor {_short(name)}: no dtype and shape)")
        out[name] = TensorInfo(dtype, tuple(shape))
    return out


def _read_at(dir_fd: int, name: str, path: Path, limit: int) -> bytes:
    """The bytes of the regular file ``name`` in the directory ``dir_fd``: never through a symbolic link, never
    blocking (a FIFO is refused, not waited on), never more than ``limit`` bytes (a device such as /dev/zero is
    refused before a byte is read)."""
    try:
        fd = os.open(name, _OPEN_FILE, dir_fd=dir_fd)
    except FileNotFoundError as error:
        raise CheckpointError(f"{path}: missing") from error
    except OSError as error:
        if os.path.islink(path):
            raise CheckpointError(f"{path}: a symbolic link (-> {os.readlink(path)}); a checkpoint's files must be "
                                  "regular files") from None  # fmt: skip
        raise CheckpointError(f"{path}: cannot open ({error.strerror})") from error
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise CheckpointError(f"{path}: not a regular file ({_file_kind(info.st_mode)}); refusing to read it")
        if info.st_size > limit:
            raise CheckpointError(f"{path}: {info.st_size:,} bytes, more than the {limit:,} a checkpoint may hold here")
        chunks, total = [], 0
        while chunk := os.read(fd, min(1 << 20, limit + 1 - total)):
            chunks.append(chunk)
            total += len(chunk)
            if total > limit:  # the file grew while being read
                raise CheckpointError(f"{path}: more than the {limit:,} bytes a checkpoint may hold here")
        return b"".join(chunks)
    except OSError as error:
        raise CheckpointError(f"{path}: cannot read ({error.strerror})") from error
    finally:
        os.close(fd)


def _file_kind(mode: int) -> str:
    for test, kind in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISDIR, "a directory"), (stat.S_ISSOCK, "a socket")):  # fmt: skip
        if test(mode):
            return kind
    return "not a plain file"


_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"')


def json_depth(data: bytes) -> int:
    """The deepest nesting of arrays and objects in the JSON text ``data``, counted without parsing it."""
    if not data:
        return 0
    text = np.frombuffer(_JSON_STRING.sub(b'""', data), dtype=np.uint8)
    step = np.isin(text, (ord("["), ord("{"))).astype(np.int64) - np.isin(text, (ord("]"), ord("}")))
    return int(np.cumsum(step).max(initial=0))


def parse_json(data: bytes, path: Path, max_depth: int, what: str = "JSON") -> Any:
    """Strict JSON from ``data``: UTF-8, at most ``max_depth`` levels deep, numbers finite (no NaN, Infinity, 1e999).
    Raises :class:`CheckpointError` naming ``path``, never RecursionError."""
    if (depth := json_depth(data)) > max_depth:
        raise CheckpointError(f"{path}: {what} nested {depth} levels deep, more than the {max_depth} allowed")

    def finite(text: str) -> float:
        value = float(text)
        if not math.isfinite(value):
            raise ValueError(f"number {text[:20]} is out of range")
        return value

    def refuse(name: str) -> float:
        raise ValueError(f"{name} is not JSON")

    try:
        return json.loads(data.decode("utf-8"), parse_float=finite, parse_constant=refuse)
    except json.JSONDecodeError as error:
        raise CheckpointError(f"{path}: invalid {what} ({error})") from error
    except (UnicodeDecodeError, ValueError, RecursionError) as error:  # ValueError: a bad number, or > 4300 digits
        raise CheckpointError(f"{path}: invalid {what} ({_one_line(error)})") from error


def _parse_meta(meta_bytes: bytes, path: Path, max_depth: int = DEFAULT_LIMITS.max_json_depth) -> dict[str, Any]:
    document = parse_json(meta_bytes, path, max_depth)
    if not isinstance(document, dict):
        raise CheckpointError(f"{path}: expected a JSON object, got {type(document).__name__}")
    if document.get("format") != FORMAT_VERSION:
        raise CheckpointError(f"{path}: format {_short(document.get('format'))}, this reader understands {FORMAT_VERSION}")
    sha, names, meta = document.get("sha256"), document.get("tensors"), document.get("meta")
    if not isinstance(sha, str) or not isinstance(meta, dict):
        raise CheckpointError(f"{path}: 'sha256' must be a string and 'meta' an object")
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names) or names != sorted(names):
        raise CheckpointError(f"{path}: 'tensors' must be a sorted list of names")
    return document


# --- random-number generators ---------------------------------------------------------------------------------------


def pack_generators(
    numpy_generators: Mapping[str, np.random.Generator],
    torch_generators: Mapping[str, torch.Generator],
) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Capture generator states as ``(tensors, meta)`` to merge into a checkpoint's tensors and meta.

    numpy states go to ``meta["rng"]["numpy"][name]`` (JSON; arrays inside a state become lists), torch states
    to the uint8 tensors ``"rng.torch.<name>"`` (pass ``torch.default_generator`` to include the global one).
    """
    numpy_states = {name: _to_json(gen.bit_generator.state) for name, gen in numpy_generators.items()}
    tensors = {f"{_TORCH_RNG_PREFIX}{name}": gen.get_state().clone() for name, gen in torch_generators.items()}
    return tensors, {_RNG_KEY: {"numpy": numpy_states, "torch": sorted(torch_generators)}}


def unpack_generators(
    tensors: Mapping[str, torch.Tensor],
    meta: Mapping[str, Any],
    numpy_generators: Mapping[str, np.random.Generator],
    torch_generators: Mapping[str, torch.Generator],
) -> None:
    """Restore, in place, generators captured by :func:`pack_generators` so they draw the same numbers again.

    The names must match the saved ones exactly, and each numpy generator must use the saved bit generator
    (e.g. PCG64); otherwise :class:`CheckpointError` is raised before any generator is changed.
    """
    rng = meta.get(_RNG_KEY)
    if not isinstance(rng, Mapping) or not isinstance(rng.get("numpy"), Mapping) or not isinstance(rng.get("torch"), list):
        raise CheckpointError(f"checkpoint meta has no generator states under {_RNG_KEY!r}")
    numpy_states: Mapping[str, Any] = rng["numpy"]
    _check_names("numpy generators", sorted(numpy_states), sorted(numpy_generators))
    _check_names("torch generators", sorted(rng["torch"]), sorted(torch_generators))
    for name, gen in numpy_generators.items():
        saved = numpy_states[name].get("bit_generator") if isinstance(numpy_states[name], Mapping) else None
        current = gen.bit_generator.state["bit_generator"]
        if saved != current:
            raise CheckpointError(f"numpy generator {name!r}: saved bit generator {saved!r}, got {current!r}")
    for name in torch_generators:
        state = tensors.get(f"{_TORCH_RNG_PREFIX}{name}")
        if state is None or state.dtype != torch.uint8:
            raise CheckpointError(f"torch generator {name!r}: no uint8 state tensor {_TORCH_RNG_PREFIX}{name!r}")
    for name, gen in numpy_generators.items():
        gen.bit_generator.state = dict(numpy_states[name])
    for name, gen in torch_generators.items():
        gen.set_state(tensors[f"{_TORCH_RNG_PREFIX}{name}"].clone())


def _to_json(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, Mapping):
        return {key: _to_json(item) for key, item in value.items()}
    return value


def _check_names(what: str, saved: list[str], given: list[str]) -> None:
    if saved != given:
        missing, unexpected = sorted(set(given) - set(saved)), sorted(set(saved) - set(given))
        raise CheckpointError(f"{what}: not in checkpoint {missing}, in checkpoint but not given {unexpected}")


# --- modules --------------------------------------------------------------------------------------------------------


def module_tensors(prefix: str, module: torch.nn.Module) -> dict[str, torch.Tensor]:
    """``module.state_dict()`` with every key written ``"<prefix>.<key>"`` (parameters and persistent buffers)."""
    out: dict[str, torch.Tensor] = {}
    for key, value in module.state_dict().items():
        if not isinstance(value, torch.Tensor):
            raise TypeError(f"{prefix}.{key} is a {type(value).__name__}, not a tensor; it cannot go in safetensors")
        out[f"{prefix}.{key}"] = value
    return out


def load_module(prefix: str, module: torch.nn.Module, tensors: Mapping[str, torch.Tensor]) -> None:
    """Load the ``"<prefix>."`` entries of ``tensors`` into ``module``, strictly.

    A key the module has but the checkpoint lacks, a ``"<prefix>."`` key the module lacks, or a shape mismatch
    raises :class:`CheckpointError` naming the key, before the module is changed.
    """
    head = f"{prefix}."
    given = {key[len(head) :]: value for key, value in tensors.items() if key.startswith(head)}
    expected = module.state_dict()
    missing = sorted(set(expected) - set(given))
    if missing:
        raise CheckpointError(f"{prefix}: missing key {head}{missing[0]}{_more(missing)}")
    unexpected = sorted(set(given) - set(expected))
    if unexpected:
        raise CheckpointError(f"{prefix}: unexpected key {head}{unexpected[0]}{_more(unexpected)}")
    for key, value in given.items():
        if value.shape != expected[key].shape:
            shapes = f"{list(value.shape)} in the checkpoint, {list(expected[key].shape)} in the module"
            raise CheckpointError(f"{prefix}: {head}{key} has shape {shapes}")
    module.load_state_dict(given, strict=True)


def _more(keys: list[str]) -> str:
    return f" (and {len(keys) - 1} more)" if len(keys) > 1 else ""


#: Keys of a training run's checkpoint meta that its readers need, with their JSON types. ``meta.json`` is not covered
#: by the content hash (that is the weights' sha256), so they are checked on every read.
RUN_META_KEYS: dict[str, type] = {"config": dict, "iteration": int, "env_steps": int, "normalizer": dict}


def read_run_checkpoint(
    directory: Path, more_keys: dict[str, type] | None = None
) -> tuple[dict[str, torch.Tensor], dict[str, Any], TrainConfig]:
    """``(tensors, meta, config)`` of a training run's checkpoint; a missing or mistyped key of :data:`RUN_META_KEYS`
    (and ``more_keys``) or a malformed config raises :class:`~hrlp.checkpoint.CheckpointError` naming the file."""
    tensors, meta = load_checkpoint(directory, required={**RUN_META_KEYS, **(more_keys or {})})
    where = Path(directory) / META_FILE
    try:
        cfg = TrainConfig.from_json(meta["config"])
    except KeyError as e:
        raise CheckpointError(f"{where}: its 'config' has no {e}") from None
    except (TypeError, ValueError, AttributeError) as e:
        raise CheckpointError(f"{where}: its 'config' is malformed ({' '.join(str(e).split())})") from None
    return tensors, meta, cfg
