"""Writing files all or nothing."""

import os
import stat

import pytest

from hrlp.atomic import atomic_path


def test_a_finished_write_replaces_the_file_and_a_failed_one_leaves_it(tmp_path):
    path = tmp_path / "sub" / "result.json"
    with atomic_path(path) as tmp:
        assert tmp.parent == path.parent and tmp.suffix == ".json"
        tmp.write_text("first")
    assert path.read_text() == "first"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask
    with pytest.raises(RuntimeError), atomic_path(path) as tmp:
        tmp.write_text("half")
        raise RuntimeError("killed mid-write")
    assert path.read_text() == "first"
    assert sorted(p.name for p in path.parent.iterdir()) == ["result.json"]
