"""Bad skill files, built for real, and a harness that feeds them to the real ``hrlp`` command.

:func:`build_bad_skill_files` writes, in a fresh directory, a skill library holding one broken entry per kind of bad
file (FIFOs, links to /dev/zero, oversized and deeply nested manifests, manifests whose numbers would allocate huge
networks, NaN or integer weights, fractional ``k``, tensors that do not fit the network, pickles that create a file
when unpickled, entries linked out of the library, ...), each derived from the shipped ``reacher`` skill with real
safetensors and JSON, plus names that are not entry names (``../x``, an absolute path). :func:`run_bad_skill_files`
runs ``hrlp skills show NAME`` and ``hrlp train-manager ... --skills NAME`` on each of them in a separate interpreter,
every command in its own forked process with a deadline (a hang is killed and counted) and an address-space limit
(reading /dev/zero or allocating a 5 GB network fails there instead of exhausting the machine), and reports what each
printed. ``tests/reliability/test_reliability_skill_files.py`` asserts on the outcomes;
``benchmarks/reliability_skill_files.py`` counts them.

Run as a script (``python bad_skill_files.py SPEC.json``) it is that separate interpreter.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

MODES = ("show", "load")
"""``show``: ``hrlp skills show NAME --library LIB``; ``load``: ``hrlp train-manager ReachAndGrip1 --skills NAME``
(the loading every Manager does before it trains)."""
GOOD = "good-reacher"
"""An intact copy of the shipped Reacher in the library: the control every bad file is told apart from."""
MEMORY_HEADROOM = 1536 * 2**20
"""Address space a command may take beyond what the interpreter holds after its imports (a skill needs ~100 KB)."""


@dataclass(frozen=True)
class BadSkill:
    """One kind of bad skill file and what refusing it must say."""

    kind: str
    """Short id; also the library entry's name for the kinds that are entries."""
    what: str
    """What is wrong, in words."""
    arg: str
    """The name given to the command."""
    expect: str
    """A fragment of the one-line error."""
    entry: bool = True
    """Whether the kind is an entry of the library (so ``hrlp skills list`` must mark it broken)."""
    modes: tuple[str, ...] = MODES
    """The commands it is given to (an empty ``--skills`` is another error: a Manager needs a skill)."""


@dataclass
class BadSkillFiles:
    """What :func:`build_bad_skill_files` wrote."""

    root: Path
    """The directory everything is in."""
    library: Path
    """The skill library holding the bad entries and :data:`GOOD`."""
    markers: Path
    """Empty directory: a payload that ran would have created a file in it."""
    cases: list[BadSkill] = field(default_factory=list)
    """Every kind built."""


@dataclass
class Outcome:
    """What one command printed and how it ended."""

    kind: str
    mode: str
    returncode: int | None
    """Exit status (None: killed after the deadline, a hang)."""
    stdout: str
    stderr: str
    seconds: float

    @property
    def hung(self) -> bool:
        return self.returncode is None

    @property
    def traceback(self) -> bool:
        return "Traceback" in self.stdout + self.stderr or self.returncode not in (None, 0, 2)

    @property
    def error_lines(self) -> list[str]:
        return [line for line in self.stderr.splitlines() if line.strip()]

    @property
    def clean_error(self) -> bool:
        """Exit 2 with exactly one line on stderr, ``error: ...``, and nothing else."""
        lines = self.error_lines
        return self.returncode == 2 and not self.traceback and len(lines) == 1 and lines[0].startswith("error: ")


class _Payload:
    """Unpickling this creates ``path``: proof that code ran while a skill was read."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self) -> tuple[object, tuple[str, str]]:
        return (open, (str(self.path), "w"))


# --- building -------------------------------------------------------------------------------------------------------


def _document(weights: bytes, names: Sequence[str], manifest: Any) -> dict[str, Any]:
    return {"format": 1, "sha256": hashlib.sha256(weights).hexdigest(), "tensors": sorted(names), "meta": manifest}


def _safetensors(tensors: dict[str, Any]) -> bytes:
    import safetensors.torch

    return safetensors.torch.save({k: v.contiguous() for k, v in tensors.items()})


def _raw_safetensors(header: dict[str, Any], data: bytes, nested: str = "") -> bytes:
    """A safetensors file with this ``header`` and ``data``; ``nested`` replaces the string ``"NESTED"``."""
    text = json.dumps(header).replace('"NESTED"', nested).encode()
    return struct.pack("<Q", len(text)) + text + data


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth


def build_bad_skill_files(root: Path) -> BadSkillFiles:
    """Write the library of bad skill files (at least 40 kinds) under ``root``; returns what was written."""
    import safetensors.torch
    import torch

    from hrlp.arm.skill_files import shipped_library_root

    root = Path(root)
    library, outside, markers = root / "library", root / "outside", root / "markers"
    for d in (library, outside, markers):
        d.mkdir(parents=True)
    source = shipped_library_root() / "reacher"
    base_weights = (source / "weights.safetensors").read_bytes()
    base_tensors = safetensors.torch.load(base_weights)
    base_manifest = json.loads((source / "meta.json").read_text())["meta"]
    out = BadSkillFiles(root, library, markers)

    def entry(kind: str) -> Path:
        d = library / kind
        d.mkdir()
        return d

    def add(kind: str, what: str, expect: str, arg: str | None = None, is_entry: bool = True,
            modes: tuple[str, ...] = MODES) -> None:  # fmt: skip
        out.cases.append(BadSkill(kind, what, kind if arg is None else arg, expect, is_entry, modes))

    def skill(kind: str, what: str, expect: str, *, tensors: dict[str, Any] | None = None,
              manifest: Any = None, weights: bytes | None = None, rehash: bool = True,
              edit: Callable[[dict[str, Any]], None] | None = None) -> Path:  # fmt: skip
        """An entry whose files are the Reacher's with ``tensors``/``manifest``/``weights`` replaced (hash recomputed
        unless ``rehash`` is False), ``edit`` applied to the manifest."""
        d = entry(kind)
        t = dict(base_tensors) if tensors is None else tensors
        w = weights if weights is not None else (_safetensors(t) if tensors is not None else base_weights)
        m = json.loads(json.dumps(base_manifest)) if manifest is None else manifest
        if edit is not None:
            edit(m)
        doc = _document(w if rehash else base_weights, sorted(t), m)
        (d / "weights.safetensors").write_bytes(w)
        (d / "meta.json").write_text(json.dumps(doc, indent=2))
        add(kind, what, expect)
        return d

    def set_key(key: str, value: Any) -> Callable[[dict[str, Any]], None]:
        return lambda m: m.__setitem__(key, value)

    def tensor_edit(name: str, fn: Callable[[torch.Tensor], torch.Tensor]) -> dict[str, Any]:
        t = dict(base_tensors)
        t[name] = fn(t[name].clone())
        return t

    # The control: an intact copy, which every command must accept.
    shutil.copytree(source, library / GOOD)

    # Files that are not regular files: a FIFO hangs a plain open(), /dev/zero is read until memory runs out.
    d = skill("weights-fifo", "weights.safetensors is a FIFO", "not a regular file (a FIFO)")
    (d / "weights.safetensors").unlink()
    os.mkfifo(d / "weights.safetensors")
    d = skill("meta-fifo", "meta.json is a FIFO", "not a regular file (a FIFO)")
    (d / "meta.json").unlink()
    os.mkfifo(d / "meta.json")
    os.mkfifo(library / "entry-fifo")
    add("entry-fifo", "the entry itself is a FIFO", "not a skill directory (a FIFO)")
    for kind, target in (("weights-dev-zero", "/dev/zero"), ("weights-dev-urandom", "/dev/urandom")):
        d = skill(kind, f"weights.safetensors is a symbolic link to {target}", "a symbolic link")
        (d / "weights.safetensors").unlink()
        (d / "weights.safetensors").symlink_to(target)
    d = skill("meta-dev-zero", "meta.json is a symbolic link to /dev/zero", "a symbolic link")
    (d / "meta.json").unlink()
    (d / "meta.json").symlink_to("/dev/zero")
    d = skill("weights-is-directory", "weights.safetensors is a directory", "not a regular file (a directory)")
    (d / "weights.safetensors").unlink()
    (d / "weights.safetensors").mkdir()

    # Links out of the library, and names that are paths: an intact skill outside the library must stay unreachable.
    shutil.copytree(source, outside / "elsewhere")
    shutil.copytree(source, root / "beside")
    (library / "entry-linked-outside").symlink_to(outside / "elsewhere")
    add("entry-linked-outside", "the entry is a symbolic link to a skill outside the library", "out of the library")
    (library / "entry-linked-to-dev").symlink_to("/dev")
    add("entry-linked-to-dev", "the entry is a symbolic link to /dev", "out of the library")
    (library / "entry-link-loop").symlink_to("entry-link-loop")
    add("entry-link-loop", "the entry is a symbolic link to itself", "not a skill directory")
    d = skill("weights-linked-outside", "weights.safetensors links to a skill's weights outside", "a symbolic link")
    (d / "weights.safetensors").unlink()
    (d / "weights.safetensors").symlink_to(outside / "elsewhere" / "weights.safetensors")
    d = skill("meta-linked-outside", "meta.json links to a manifest outside", "a symbolic link")
    (d / "meta.json").unlink()
    (d / "meta.json").symlink_to(outside / "elsewhere" / "meta.json")
    add("name-parent", "`show ../beside`: a skill beside the library", "not a plain entry name", "../beside", False)
    add("name-absolute", "`show /abs/path`: a skill anywhere", "not a plain entry name", str(outside / "elsewhere"), False)
    add("name-nested", "`show a/b`: a path inside the library", "not a plain entry name", f"{GOOD}/../{GOOD}", False)
    add("name-dot-dot", "`show ..`", "not a plain entry name", "..", False)
    add("name-empty", "an empty name", "not a plain entry name", "", False, ("show",))
    shutil.copytree(source, library / ".hidden")
    add("name-hidden", "`show .hidden`: a hidden directory", "not a plain entry name", ".hidden", False)

    # Missing, huge, deep or malformed files.
    d = skill("meta-missing", "no meta.json", "meta.json: missing")
    (d / "meta.json").unlink()
    d = skill("weights-missing", "no weights.safetensors", "weights.safetensors: missing")
    (d / "weights.safetensors").unlink()
    entry("entry-empty")
    add("entry-empty", "an empty directory", "meta.json: missing")
    d = entry("python-files")
    (d / "__init__.py").write_text(f"open({str(markers / 'python-files')!r}, 'w')\n")
    (d / "skill.py").write_text(f"open({str(markers / 'python-files')!r}, 'w')\n")
    add("python-files", "Python files instead of a skill (never imported)", "meta.json: missing")
    d = skill("weights-huge", "a 100 MB weights file (sparse)", "more than the")
    os.truncate(d / "weights.safetensors", 100 * 2**20)
    d = skill("meta-huge", "a 100 MB manifest", "more than the")
    with open(d / "meta.json", "r+b") as f:
        f.seek(100 * 2**20)
        f.write(b" ")
    skill("meta-deep", "a manifest nested 200,000 levels deep", "levels deep", edit=set_key("lineage", "NESTED"))
    text = (library / "meta-deep" / "meta.json").read_text().replace('"NESTED"', _nested(200_000))
    (library / "meta-deep" / "meta.json").write_text(text)
    skill("meta-deep-20", "a manifest nested 20 levels deep", "levels deep", edit=set_key("lineage", "NESTED"))
    text = (library / "meta-deep-20" / "meta.json").read_text().replace('"NESTED"', _nested(20))
    (library / "meta-deep-20" / "meta.json").write_text(text)
    d = skill("meta-not-json", "meta.json is not JSON", "invalid JSON")
    (d / "meta.json").write_text("{'k': 15,")
    d = skill("meta-not-utf8", "meta.json is not UTF-8", "invalid JSON")
    (d / "meta.json").write_bytes(b'{"format": 1, "meta": "\xff\xfe"}')
    d = skill("meta-is-array", "meta.json holds an array", "expected a JSON object")
    (d / "meta.json").write_text("[1, 2, 3]")
    skill("meta-nan", "a NaN in the manifest", "not JSON", edit=set_key("k", "NAN"))
    text = (library / "meta-nan" / "meta.json").read_text().replace('"NAN"', "NaN")
    (library / "meta-nan" / "meta.json").write_text(text)
    skill("meta-huge-number", "obs_dim 1e999 (infinite once parsed)", "out of range", edit=set_key("obs_dim", "BIG"))
    text = (library / "meta-huge-number" / "meta.json").read_text().replace('"BIG"', "1e999")
    (library / "meta-huge-number" / "meta.json").write_text(text)
    skill("meta-huge-int", "an integer of 5,000 digits", "invalid JSON", edit=set_key("obs_dim", "BIG"))
    text = (library / "meta-huge-int" / "meta.json").read_text().replace('"BIG"', "7" * 5000)
    (library / "meta-huge-int" / "meta.json").write_text(text)
    d = skill("meta-format-99", "an unknown format version", "format 99")
    doc = json.loads((d / "meta.json").read_text())
    (d / "meta.json").write_text(json.dumps({**doc, "format": 99}))
    d = skill("meta-no-meta", "meta.json without its 'meta' object", "'meta' an object")
    doc = json.loads((d / "meta.json").read_text())
    del doc["meta"]
    (d / "meta.json").write_text(json.dumps(doc))
    d = skill("meta-tensor-names", "meta.json lists other tensor names", "tensor names differ")
    doc = json.loads((d / "meta.json").read_text())
    doc["tensors"] = sorted([*doc["tensors"], "policy.extra"])
    (d / "meta.json").write_text(json.dumps(doc))

    # Weights that are not what the manifest says.
    data = bytearray(base_weights)
    data[-5] ^= 0x40
    skill("weights-modified", "a flipped byte, hash not updated", "does not match", weights=bytes(data), rehash=False)
    skill("weights-truncated", "truncated weights, hash updated", "not a valid safetensors", weights=base_weights[:-100])
    skill("weights-pickle", "a pickle whose loading creates a file", "not a valid safetensors",
          weights=pickle.dumps({"w": _Payload(markers / "weights-pickle")}))  # fmt: skip
    d = skill("weights-torch-save", "torch.save output whose loading creates a file", "not a valid safetensors")
    torch.save({"w": _Payload(markers / "weights-torch-save")}, d / "weights.safetensors")
    doc = json.loads((d / "meta.json").read_text())
    doc["sha256"] = hashlib.sha256((d / "weights.safetensors").read_bytes()).hexdigest()
    (d / "meta.json").write_text(json.dumps(doc))
    d = skill("meta-pickle", "meta.json is a pickle whose loading creates a file", "invalid JSON")
    (d / "meta.json").write_bytes(pickle.dumps({"meta": _Payload(markers / "meta-pickle")}))
    skill("weights-header-length", "a safetensors header claiming 2**60 bytes", "header of",
          weights=struct.pack("<Q", 2**60) + base_weights[8:])  # fmt: skip
    skill("weights-header-deep", "a safetensors header nested 100,000 levels deep", "levels deep",
          weights=_raw_safetensors({"__metadata__": "NESTED"}, b"", _nested(100_000)))  # fmt: skip
    header = {name: {"dtype": "F32" if name.startswith("policy") else "F64", "shape": list(t.shape),
                     "data_offsets": [0, 4]} for name, t in base_tensors.items()}  # fmt: skip
    skill("weights-header-lies", "a header whose shapes the data do not hold", "not a valid safetensors",
          weights=_raw_safetensors(header, b"\0\0\0\0"))  # fmt: skip

    # Manifest numbers that would allocate networks before the shape check, and a network that does not fit.
    skill("obs-dim-huge", "obs_dim 10,000,000 (a 5 GB network)", "'obs_dim'", edit=set_key("obs_dim", 10_000_000))
    skill("hidden-huge", "hidden [100000, 100000] (a 40 GB network)", "has shape",
          edit=set_key("hidden", [100_000, 100_000]))  # fmt: skip
    skill("hidden-other", "hidden [32, 32] beside 64-wide weights", "has shape", edit=set_key("hidden", [32, 32]))
    skill("hidden-deeper", "three hidden layers beside weights of two", "do not fit the network",
          edit=set_key("hidden", [64, 64, 64]))  # fmt: skip
    skill("hidden-not-list", "hidden '64,64'", "'hidden'", edit=set_key("hidden", "64,64"))
    skill("hidden-zero", "a hidden layer of width 0", "'hidden'", edit=set_key("hidden", [0, 64]))
    skill("act-dim-other", "act_dim 8 for a 9-joint arm", "'act_dim'", edit=set_key("act_dim", 8))
    # Named observation features: unknown names, a list that is not one, and features the weights were not trained on.
    skill("features-unknown", "a feature no environment computes", "unknown observation feature",
          edit=set_key("features", ["__import__('os')"]))  # fmt: skip
    skill("features-not-list", "features given as a string", "must be a list", edit=set_key("features", "capsule_pose"))
    skill("features-twice", "one feature named twice", "twice", edit=set_key("features", ["capsule_pose", "capsule_pose"]))
    skill("features-unfitted", "features beside weights for 27 numbers", "'obs_dim'",
          edit=set_key("features", ["capsule_pose"]))  # fmt: skip
    t = tensor_edit("policy.mean_net.0.weight", lambda w: w[:, :26])
    skill("block-misfit", "a first layer for 26 observations, not 27", "has shape", tensors=t)
    t = tensor_edit("normalizer.mean", lambda w: w[:20])
    skill("normalizer-misfit", "normaliser statistics of 20 observations, not 27", "has shape", tensors=t)
    t = dict(base_tensors)
    t["policy.mean_net.6.weight"] = torch.zeros(9, 9)
    skill("extra-tensor", "a tensor the network does not have", "do not fit the network", tensors=t)
    t = dict(base_tensors)
    del t["policy.log_std"]
    skill("missing-tensor", "no log_std", "do not fit the network", tensors=t)

    # Degenerate values that used to load silently.
    t = tensor_edit("policy.mean_net.0.weight", lambda w: w.index_fill_(0, torch.tensor([3]), float("nan")))
    skill("weights-nan", "NaN weights", "holds NaN or inf", tensors=t)
    t = tensor_edit("policy.mean_net.4.bias", lambda w: w.fill_(float("inf")))
    skill("weights-inf", "infinite biases", "holds NaN or inf", tensors=t)
    t = tensor_edit("normalizer.mean", lambda w: w.fill_(float("nan")))
    skill("normalizer-nan", "NaN observation means", "holds NaN or inf", tensors=t)
    t = tensor_edit("normalizer.var", lambda w: -w)
    skill("normalizer-negative-var", "negative variances", "is negative", tensors=t)
    t = tensor_edit("policy.mean_net.0.weight", lambda w: w.to(torch.int32))
    skill("weights-int", "integer weights (zero torques)", "must be floating point", tensors=t)
    t = tensor_edit("policy.mean_net.2.weight", lambda w: w > 0)
    skill("weights-bool", "boolean weights", "must be floating point", tensors=t)
    for kind, value, what in (("k-fraction", 1.5, "fractional"), ("k-bool", True, "boolean"), ("k-zero", 0, "zero"),
                              ("k-negative", -3, "negative"), ("k-huge", 10**12, "a trillion"),
                              ("k-string", "15", "a string")):  # fmt: skip
        skill(kind, f"a {what} default duration k ({value!r})", "'k'", edit=set_key("k", value))
    skill("k-missing", "no default duration k", "'k'", edit=lambda m: m.pop("k"))
    skill("kind-flat", "a flat run's checkpoint, not a skill", "not a skill", edit=set_key("kind", "flat"))
    skill("task-unknown", "an unknown task", "unknown task", edit=set_key("task", "__import__('os').system('id')"))
    skill("task-not-string", "a task that is a list", "unknown task", edit=set_key("task", ["Reacher"]))
    skill("task-markup", "a task that is terminal markup", "unknown task", edit=set_key("task", "[/bold]"))
    # through `train-manager` the line reaches hrlp.cli._fail, which does not escape markup yet (docs/reliability.md)
    out.cases[-1] = BadSkill(**{**asdict(out.cases[-1]), "modes": ("show",)})
    skill("param-other-dim", "5 parameters for a 3-parameter task", "do not match",
          edit=lambda m: m["param"].update(dim=5, low=[0] * 5, high=[1] * 5))  # fmt: skip
    skill("param-malformed", "'param' is a string", "'param' is malformed", edit=set_key("param", "x"))
    skill("normalizer-shape", "a normaliser for 26 observations", "'normalizer'",
          edit=lambda m: m["normalizer"].update(shape=[26]))  # fmt: skip
    skill("normalizer-clip", "a negative clip", "normaliser settings", edit=lambda m: m["normalizer"].update(clip=-1))
    skill("trained-missing", "no record of its training", "'trained'", edit=lambda m: m.pop("trained"))
    skill("manifest-is-list", "the caller's meta is a list", "'meta' an object", manifest=[1, 2])
    return out


# --- running --------------------------------------------------------------------------------------------------------


def run_bad_skill_files(files: BadSkillFiles, kinds: Mapping[str, Collection[str] | None] | None = None,
                        deadline: float = 8.0, extra: Sequence[tuple[str, list[str]]] = (),
                        parallel: int = 2) -> list[Outcome]:  # fmt: skip
    """Run the real ``hrlp`` on the cases, plus ``extra`` commands (``(label, argv)``), in one separate interpreter:
    each command in a forked process with ``deadline`` seconds and :data:`MEMORY_HEADROOM` of address space, up to
    ``parallel`` at a time.

    ``kinds`` maps each mode to run to the kinds it runs (None: all of them); by default every kind in every mode.
    Returns one :class:`Outcome` per command (mode ``extra`` for the extra ones)."""
    kinds = dict.fromkeys(MODES) if kinds is None else kinds
    commands = [(c.kind, mode, _argv(mode, c.arg, files, c.kind)) for mode, wanted in kinds.items() for c in files.cases
                if mode in c.modes and (wanted is None or c.kind in wanted)]  # fmt: skip
    commands += [(label, "extra", argv) for label, argv in extra]
    spec = files.root / "commands.json"
    warm_up = [_argv("show", GOOD, files), _argv("load", "no-such-skill", files, "warm-up")]
    spec.write_text(json.dumps({"commands": commands, "deadline": deadline, "warm_up": warm_up, "parallel": parallel}))
    env = {**os.environ, "HRLP_SKILLS": str(files.root / "no-user-library"), "COLUMNS": "200", "PYTHONHASHSEED": "0"}
    budget = 60 + len(commands) * (deadline + 2)
    r = subprocess.run([sys.executable, __file__, str(spec)], capture_output=True, text=True, timeout=budget, env=env,
                       cwd=files.root)  # fmt: skip
    if r.returncode != 0:
        raise RuntimeError(f"the harness failed (exit {r.returncode}): {r.stderr[-3000:]}")
    return [Outcome(**o) for o in json.loads(r.stdout)]


def _argv(mode: str, name: str, files: BadSkillFiles, label: str = "run") -> list[str]:
    """The command line of ``mode`` for the skill ``name`` (``label`` names the run directory of a Manager)."""
    if mode == "show":
        return ["skills", "show", name, "--library", str(files.library)]
    if mode == "load":
        return ["train-manager", "ReachAndGrip1", "--skills", name, "--library", str(files.library), "--steps", "16",
                "--batch-steps", "16", "--num-envs", "1", "--run-dir", str(files.root / "runs" / label)]  # fmt: skip
    raise ValueError(f"unknown mode {mode!r} (known: {', '.join(MODES)})")


def code_executed(files: BadSkillFiles) -> list[str]:
    """The payloads that ran: files they created in :attr:`BadSkillFiles.markers`."""
    return sorted(p.name for p in files.markers.iterdir())


def summarise(files: BadSkillFiles, outcomes: Sequence[Outcome]) -> dict[str, Any]:
    """Counts over the outcomes of the bad cases (the control and ``extra`` commands left out)."""
    bad = [o for o in outcomes if o.mode in MODES]
    return {
        "kinds": len({o.kind for o in bad}),
        "commands": len(bad),
        "code_executed": len(code_executed(files)),
        "hangs": sum(o.hung for o in bad),
        "tracebacks": sum(o.traceback and not o.hung for o in bad),
        "accepted": sum(o.returncode == 0 for o in bad),
        "not_one_line": sum(o.returncode == 2 and not o.clean_error for o in bad),
        "max_seconds": max((o.seconds for o in bad), default=0.0),
    }


def _child(command: Any, argv: list[str], out: Path, err: Path) -> None:
    """In the forked process: run ``hrlp ARGV`` (``command``: the click command of ``hrlp.cli.app``, built once) with
    stdout/stderr to files, as ``python -m hrlp`` would."""
    import resource
    import traceback

    code = 1
    try:
        fd_out, fd_err = os.open(out, os.O_WRONLY | os.O_CREAT), os.open(err, os.O_WRONLY | os.O_CREAT)
        os.dup2(fd_out, 1)
        os.dup2(fd_err, 2)
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[0])
        limit = pages * os.sysconf("SC_PAGE_SIZE") + MEMORY_HEADROOM
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        try:
            command.main(args=argv, prog_name="hrlp")
            code = 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        except BaseException:
            traceback.print_exc()
            code = 1
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def _harness(spec_path: Path) -> None:
    """The separate interpreter: import once, then fork one process per command."""
    import contextlib
    import io
    import signal

    import rich.markup  # noqa: F401 (imported once here, not in every forked command)
    import torch
    import typer.main

    import hrlp.cli
    import hrlp.skills.library
    import hrlp.train

    torch.set_num_threads(1)  # before any torch operation: no thread pool for the forked processes to inherit
    command = typer.main.get_command(hrlp.cli.app)
    spec = json.loads(spec_path.read_text())
    for argv in spec["warm_up"]:  # in this process: the lazy imports and first-call costs, paid once, not per command
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            with contextlib.suppress(SystemExit):
                command.main(args=argv, prog_name="hrlp")
    commands, deadline = spec["commands"], spec["deadline"]
    results: list[dict[str, Any] | None] = [None] * len(commands)
    running: dict[int, tuple[int, float]] = {}  # pid: (index of the command, start)
    parallel = max(1, min(spec.get("parallel", 2), os.cpu_count() or 1))
    with tempfile.TemporaryDirectory() as tmp:
        files = [(Path(tmp) / f"{i}.out", Path(tmp) / f"{i}.err") for i in range(len(commands))]

        def finish(pid: int, code: int | None) -> None:
            i, start = running.pop(pid)
            text = [p.read_text(errors="replace")[-100_000:] if p.exists() else "" for p in files[i]]
            kind, mode, _ = commands[i]
            results[i] = asdict(Outcome(kind, mode, code, text[0], text[1], round(time.perf_counter() - start, 3)))

        queue = list(range(len(commands)))
        while queue or running:
            while queue and len(running) < parallel:
                i = queue.pop(0)
                pid = os.fork()
                if pid == 0:
                    _child(command, commands[i][2], *files[i])
                running[pid] = (i, time.perf_counter())
            for pid, (_, start) in list(running.items()):
                done, status = os.waitpid(pid, os.WNOHANG)
                if done:
                    finish(pid, os.waitstatus_to_exitcode(status))
                elif time.perf_counter() - start > deadline:  # a hang: killed, and counted as one
                    os.kill(pid, signal.SIGKILL)
                    os.waitpid(pid, 0)
                    finish(pid, None)
            time.sleep(0.002)
    json.dump(results, sys.stdout)


if __name__ == "__main__":
    _harness(Path(sys.argv[1]))
