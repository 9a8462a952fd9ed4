"""Checkpoints: round trip, atomic replacement under simulated crashes, rejection of damaged or hostile files."""

from __future__ import annotations

import hashlib
import json
import os
import pickle
from pathlib import Path

import numpy as np
import pytest
import torch

from hrlp.checkpoint import (
    META_FILE,
    WEIGHTS_FILE,
    CheckpointError,
    load_checkpoint,
    load_module,
    module_tensors,
    pack_generators,
    resolve_checkpoint,
    save_checkpoint,
    unpack_generators,
)


def _tensors(scale: float = 1.0) -> dict[str, torch.Tensor]:
    return {
        "w": scale * torch.arange(12, dtype=torch.float32).reshape(3, 4),
        "w_t": (scale * torch.arange(12, dtype=torch.float64).reshape(3, 4)).t(),  # non-contiguous view
        "count": torch.tensor(7, dtype=torch.int64),
        "empty": torch.zeros(0, 2),
    }


def _assert_same(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> None:
    assert sorted(a) == sorted(b)
    for name in a:
        assert a[name].dtype == b[name].dtype, name
        assert torch.equal(a[name], b[name]), name


def _siblings(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.parent.iterdir() if p.name.startswith(f".{directory.name}."))


def test_round_trip(tmp_path: Path) -> None:
    ckpt = tmp_path / "runs" / "ckpt"
    meta = {"iteration": 3, "name": "reacher", "loss": [0.5, 0.25], "nested": {"ok": True, "none": None}}
    assert save_checkpoint(ckpt, _tensors(), meta) == ckpt
    tensors, loaded_meta = load_checkpoint(ckpt)
    _assert_same(tensors, _tensors())
    assert tensors["w_t"].is_contiguous()
    assert loaded_meta == meta
    document = json.loads((ckpt / META_FILE).read_text())
    assert document["format"] == 1
    assert document["tensors"] == sorted(_tensors())
    assert document["sha256"] == hashlib.sha256((ckpt / WEIGHTS_FILE).read_bytes()).hexdigest()
    assert sorted(p.name for p in ckpt.iterdir()) == [META_FILE, WEIGHTS_FILE]
    assert _siblings(ckpt) == []


def test_overwrite_replaces_and_leaves_no_siblings(tmp_path: Path) -> None:
    ckpt = tmp_path / "ckpt"
    save_checkpoint(ckpt, _tensors(1.0), {"iteration": 1})
    save_checkpoint(ckpt, {"only": torch.ones(2)}, {"iteration": 2})
    tensors, meta = load_checkpoint(ckpt)
    assert meta == {"iteration": 2}
    _assert_same(tensors, {"only": torch.ones(2)})
    assert _siblings(ckpt) == []


def test_bad_meta_and_tensors_rejected_before_writing(tmp_path: Path) -> None:
    ckpt = tmp_path / "ckpt"
    with pytest.raises(ValueError, match="strict JSON"):
        save_checkpoint(ckpt, _tensors(), {"loss": float("nan")})
    with pytest.raises(ValueError, match="strict JSON"):
        save_checkpoint(ckpt, _tensors(), {"array": np.zeros(2)})
    with pytest.raises(TypeError, match="'x'"):
        save_checkpoint(ckpt, {"x": np.zeros(2)}, {})  # type: ignore[dict-item]
    assert not tmp_path.joinpath("ckpt").exists()
    assert _siblings(ckpt) == []


def test_refuses_to_replace_a_directory_that_is_not_a_checkpoint(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "notes.txt").write_text("precious")
    with pytest.raises(CheckpointError, match=r"notes\.txt"):
        save_checkpoint(run_dir, _tensors(), {})
    assert (run_dir / "notes.txt").read_text() == "precious"


@pytest.mark.parametrize("failing_call", [1, 2])
def test_failed_rename_keeps_previous_checkpoint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, failing_call: int) -> None:
    """os.replace fails on the first rename (old aside) or the second (new into place): the old checkpoint survives."""
    ckpt = tmp_path / "ckpt"
    save_checkpoint(ckpt, _tensors(1.0), {"iteration": 1})
    real_replace = os.replace
    calls = []

    def flaky_replace(src: os.PathLike[str], dst: os.PathLike[str]) -> None:
        calls.append((src, dst))
        if len(calls) == failing_call:
            raise OSError(28, "No space left on device")
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", flaky_replace)
    with pytest.raises(OSError, match="No space"):
        save_checkpoint(ckpt, _tensors(2.0), {"iteration": 2})
    monkeypatch.setattr(os, "replace", real_replace)

    tensors, meta = load_checkpoint(ckpt)
    assert meta == {"iteration": 1}
    _assert_same(tensors, _tensors(1.0))
    assert _siblings(ckpt) == []
    save_checkpoint(ckpt, _tensors(3.0), {"iteration": 3})
    assert load_checkpoint(ckpt)[1] == {"iteration": 3}


def test_recovers_from_kill_between_renames(tmp_path: Path) -> None:
    """On-disk state of a process killed after moving NAME aside and before moving the new copy in."""
    ckpt = tmp_path / "ckpt"
    save_checkpoint(ckpt, _tensors(1.0), {"iteration": 1})
    os.rename(ckpt, tmp_path / ".ckpt.old-dead")
    half_written = tmp_path / ".ckpt.tmp-dead"
    half_written.mkdir()
    (half_written / WEIGHTS_FILE).write_bytes(b"\x00" * 5)

    assert resolve_checkpoint(ckpt) == tmp_path / ".ckpt.old-dead"
    tensors, meta = load_checkpoint(ckpt)
    assert meta == {"iteration": 1}
    _assert_same(tensors, _tensors(1.0))
    assert not ckpt.exists()  # readers never modify the file system

    save_checkpoint(ckpt, _tensors(2.0), {"iteration": 2})
    tensors, meta = load_checkpoint(ckpt)
    assert meta == {"iteration": 2}
    _assert_same(tensors, _tensors(2.0))
    assert _siblings(ckpt) == []


def test_kill_while_deleting_old_copy_is_harmless(tmp_path: Path) -> None:
    ckpt = tmp_path / "ckpt"
    save_checkpoint(ckpt, _tensors(2.0), {"iteration": 2})
    stale = tmp_path / ".ckpt.old-dead"
    stale.mkdir()
    (stale / META_FILE).write_text("{")  # partly deleted previous checkpoint
    assert resolve_checkpoint(ckpt) == ckpt
    assert load_checkpoint(ckpt)[1] == {"iteration": 2}
    save_checkpoint(ckpt, _tensors(3.0), {"iteration": 3})
    assert _siblings(ckpt) == []


def test_missing_checkpoint_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="no checkpoint"):
        load_checkpoint(tmp_path / "nowhere")
    ckpt = save_checkpoint(tmp_path / "ckpt", _tensors(), {})
    (ckpt / WEIGHTS_FILE).unlink()
    with pytest.raises(CheckpointError, match=rf"{WEIGHTS_FILE}: missing"):
        load_checkpoint(ckpt)


def test_flipped_byte_is_detected(tmp_path: Path) -> None:
    ckpt = save_checkpoint(tmp_path / "ckpt", _tensors(), {})
    data = bytearray((ckpt / WEIGHTS_FILE).read_bytes())
    data[-3] ^= 0x01  # inside the tensor data: still parses as safetensors, only the hash can tell
    (ckpt / WEIGHTS_FILE).write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match=rf"{WEIGHTS_FILE}: sha256 .* does not match"):
        load_checkpoint(ckpt)


@pytest.mark.parametrize("rehash", [False, True], ids=["hash-mismatch", "hash-updated"])
def test_truncated_file_is_rejected(tmp_path: Path, rehash: bool) -> None:
    ckpt = save_checkpoint(tmp_path / "ckpt", _tensors(), {})
    data = (ckpt / WEIGHTS_FILE).read_bytes()[:-10]
    (ckpt / WEIGHTS_FILE).write_bytes(data)
    if rehash:  # a consistent-looking but truncated file must still be rejected by the parser
        document = json.loads((ckpt / META_FILE).read_text())
        document["sha256"] = hashlib.sha256(data).hexdigest()
        (ckpt / META_FILE).write_text(json.dumps(document))
    with pytest.raises(CheckpointError, match=WEIGHTS_FILE) as info:
        load_checkpoint(ckpt)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ('{"format": 1, "sha256": ', "invalid JSON"),
        ("[1, 2]", "expected a JSON object"),
        ('{"format": 99, "sha256": "", "tensors": [], "meta": {}}', "format 99"),
        ('{"format": 1, "sha256": "", "tensors": ["b", "a"], "meta": {}}', "'tensors' must be a sorted list"),
    ],
)
def test_bad_meta_json_is_rejected(tmp_path: Path, text: str, problem: str) -> None:
    ckpt = save_checkpoint(tmp_path / "ckpt", _tensors(), {})
    (ckpt / META_FILE).write_text(text)
    with pytest.raises(CheckpointError, match=rf"{META_FILE}: {problem}"):
        load_checkpoint(ckpt)


def test_tensor_names_must_match_meta(tmp_path: Path) -> None:
    ckpt = save_checkpoint(tmp_path / "ckpt", _tensors(), {})
    document = json.loads((ckpt / META_FILE).read_text())
    document["tensors"] = sorted([*document["tensors"], "ghost"])
    (ckpt / META_FILE).write_text(json.dumps(document))
    with pytest.raises(CheckpointError, match=r"missing \['ghost'\]"):
        load_checkpoint(ckpt)


class _Exploit:
    """Unpickling this creates the file ``path``: proof that code ran on load."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self) -> tuple[object, tuple[str, str]]:
        return (open, (str(self.path), "w"))


@pytest.mark.parametrize("writer", ["pickle", "torch.save"])
def test_loader_never_unpickles(tmp_path: Path, writer: str) -> None:
    ckpt = save_checkpoint(tmp_path / "ckpt", _tensors(), {})
    sentinel = tmp_path / "pwned"
    weights = ckpt / WEIGHTS_FILE
    if writer == "pickle":
        weights.write_bytes(pickle.dumps({"w": _Exploit(sentinel)}))
    else:
        torch.save({"w": _Exploit(sentinel)}, weights)
    document = json.loads((ckpt / META_FILE).read_text())
    document["sha256"] = hashlib.sha256(weights.read_bytes()).hexdigest()  # so the hash check cannot be what stops it
    (ckpt / META_FILE).write_text(json.dumps(document))
    assert not sentinel.exists()
    with pytest.raises(CheckpointError, match="not a valid safetensors file"):
        load_checkpoint(ckpt)
    assert not sentinel.exists()


@pytest.mark.parametrize("bit_generator", [np.random.PCG64, np.random.MT19937, np.random.Philox])
def test_generators_round_trip_through_a_checkpoint(tmp_path: Path, bit_generator: type) -> None:
    rng = np.random.Generator(bit_generator(1))
    torch_rng = torch.Generator().manual_seed(2)
    rng.normal(size=5), torch.randn(5, generator=torch_rng)  # advance past the seed
    tensors, meta = pack_generators({"env": rng}, {"policy": torch_rng})
    save_checkpoint(tmp_path / "ckpt", tensors, {"iteration": 4, **meta})
    expected_np, expected_torch = rng.normal(size=6), torch.randn(6, generator=torch_rng)

    loaded_tensors, loaded_meta = load_checkpoint(tmp_path / "ckpt")
    resumed = np.random.Generator(bit_generator(99))
    resumed_torch = torch.Generator().manual_seed(99)
    unpack_generators(loaded_tensors, loaded_meta, {"env": resumed}, {"policy": resumed_torch})
    np.testing.assert_array_equal(resumed.normal(size=6), expected_np)
    assert torch.equal(torch.randn(6, generator=resumed_torch), expected_torch)


def test_default_torch_generator_round_trip() -> None:
    tensors, meta = pack_generators({}, {"global": torch.default_generator})
    expected = torch.rand(4)
    unpack_generators(tensors, meta, {}, {"global": torch.default_generator})
    assert torch.equal(torch.rand(4), expected)


def test_unpack_generators_rejects_mismatches() -> None:
    tensors, meta = pack_generators({"env": np.random.default_rng(0)}, {"policy": torch.Generator()})
    with pytest.raises(CheckpointError, match=r"not in checkpoint \['other'\]"):
        unpack_generators(
            tensors, meta, {"env": np.random.default_rng(1), "other": np.random.default_rng(2)}, {"policy": torch.Generator()}
        )
    with pytest.raises(CheckpointError, match=r"in checkpoint but not given \['policy'\]"):
        unpack_generators(tensors, meta, {"env": np.random.default_rng(1)}, {})
    untouched = np.random.default_rng(5)
    before = untouched.bit_generator.state
    with pytest.raises(CheckpointError, match="saved bit generator 'PCG64', got 'MT19937'"):
        unpack_generators(tensors, meta, {"env": np.random.Generator(np.random.MT19937(1))}, {"policy": torch.Generator()})
    with pytest.raises(CheckpointError, match="no generator states"):
        unpack_generators(tensors, {}, {"env": untouched}, {})
    assert untouched.bit_generator.state == before


def _net() -> torch.nn.Module:
    return torch.nn.Sequential(torch.nn.Linear(3, 4), torch.nn.BatchNorm1d(4), torch.nn.Linear(4, 2))


def test_module_round_trip(tmp_path: Path) -> None:
    torch.manual_seed(0)
    source, target = _net(), _net()
    source[1].running_mean.fill_(0.5)
    save_checkpoint(tmp_path / "ckpt", {**module_tensors("policy", source), "other.x": torch.ones(1)}, {})
    tensors, _ = load_checkpoint(tmp_path / "ckpt")
    assert "policy.1.running_mean" in tensors
    load_module("policy", target, tensors)
    for (name, a), b in zip(source.state_dict().items(), target.state_dict().values(), strict=True):
        assert torch.equal(a, b), name


def test_load_module_is_strict() -> None:
    tensors = module_tensors("policy", _net())
    target = _net()
    before = {k: v.clone() for k, v in target.state_dict().items()}

    missing = {k: v for k, v in tensors.items() if k != "policy.2.bias"}
    with pytest.raises(CheckpointError, match=r"missing key policy\.2\.bias"):
        load_module("policy", target, missing)
    with pytest.raises(CheckpointError, match=r"unexpected key policy\.3\.weight"):
        load_module("policy", target, {**tensors, "policy.3.weight": torch.zeros(1)})
    with pytest.raises(CheckpointError, match=r"policy\.0\.weight has shape \[5, 3\] in the checkpoint, \[4, 3\]"):
        load_module("policy", target, {**tensors, "policy.0.weight": torch.zeros(5, 3)})
    with pytest.raises(CheckpointError, match=r"value: missing key value\.0\.bias \(and 8 more\)"):
        load_module("value", target, tensors)
    for key, value in target.state_dict().items():
        assert torch.equal(value, before[key]), key
