"""Running normaliser: exact parallel merge, freezing, clipping, pickle-free persistence."""

import json

import numpy as np
import pytest
import torch
from safetensors.torch import load_file, save_file

from hrlp.policies.normalizer import RunningNormalizer


def _data(seed=0):
    rng = np.random.default_rng(seed)
    return [rng.normal(loc=[1.0, -3.0, 10.0], scale=[0.5, 2.0, 7.0], size=(n, 3)) for n in (1, 7, 50, 3, 200)]


def test_merged_batches_equal_numpy_statistics_of_concatenation():
    batches = _data()
    norm = RunningNormalizer(3)
    for b in batches:
        norm.update(b)
    full = np.concatenate(batches)
    np.testing.assert_allclose(norm.mean, full.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(norm.var, full.var(axis=0), rtol=1e-10)
    assert norm.count == len(full)


def test_single_observation_and_tensor_updates():
    rows = np.concatenate(_data(1))
    norm = RunningNormalizer((3,))
    for r in rows[:10]:
        norm.update(r)  # one [obs_dim] observation at a time
    norm.update(torch.as_tensor(rows[10:]))
    np.testing.assert_allclose(norm.mean, rows.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(norm.var, rows.var(axis=0), rtol=1e-10)


def test_normalize_known_answer_clip_and_types():
    norm = RunningNormalizer(2, clip=2.0, eps=0.0)
    norm.load_state_dict({"mean": [1.0, -1.0], "var": [4.0, 0.25], "count": 10.0})
    x = np.array([[3.0, -1.5], [1.0, 10.0]], dtype=np.float32)
    out = norm.normalize(x)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, [[1.0, -1.0], [0.0, 2.0]])  # 22 clipped to 2
    t = norm.normalize(torch.as_tensor(x))
    assert isinstance(t, torch.Tensor) and t.dtype == torch.float32
    np.testing.assert_allclose(t.numpy(), out)


def test_identity_before_first_update():
    x = np.array([[0.5, -2.0]])
    np.testing.assert_allclose(RunningNormalizer(2, clip=None, eps=0.0).normalize(x), x)


def test_frozen_does_not_update():
    norm = RunningNormalizer(3)
    norm.update(_data()[2])
    before = norm.state_dict()
    norm.freeze()
    norm.update(_data()[4])
    norm(_data()[3])
    after = norm.state_dict()
    for key in before:
        assert torch.equal(before[key], after[key])
    norm.unfreeze()
    norm.update(_data()[4])
    assert norm.count > float(before["count"])


def test_state_round_trip_through_safetensors_and_json(tmp_path):
    norm = RunningNormalizer(3, clip=5.0)
    for b in _data(2):
        norm.update(b)
    norm.freeze()
    save_file(norm.state_dict(), tmp_path / "norm.safetensors")
    (tmp_path / "norm.json").write_text(json.dumps(norm.config()))
    restored = RunningNormalizer.from_config(
        json.loads((tmp_path / "norm.json").read_text()), load_file(tmp_path / "norm.safetensors")
    )
    assert restored.frozen and restored.clip == 5.0
    x = np.concatenate(_data(3))
    np.testing.assert_array_equal(restored.normalize(x), norm.normalize(x))
    assert restored.count == norm.count


def test_rejects_bad_settings():
    with pytest.raises(ValueError, match="clip"):
        RunningNormalizer(3, clip=0.0)
    with pytest.raises(ValueError, match="eps"):
        RunningNormalizer(3, eps=-1.0)
