"""Outputs are written whole or not at all, with the mode the user's umask gives."""

import os
import stat

import pytest

from pipeline.outputs import atomic
from pipeline.outputs.atomic import atomic_path, write_json


@pytest.fixture(params=["anonymous", "beside"])
def way(request, monkeypatch):
    """Both ways of writing: the anonymous O_TMPFILE file, and the fallback beside the target."""
    if request.param == "beside":
        monkeypatch.setattr(atomic, "_anonymous_file", lambda folder: None)
    return request.param


@pytest.fixture
def umask():
    old = os.umask(0o022)
    yield lambda m: os.umask(m)
    os.umask(old)


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o002, 0o664), (0o077, 0o600)])
def test_outputs_honour_the_umask(tmp_path, umask, mask, mode, way):
    umask(mask)
    write_json(tmp_path / "a.json", {"x": 1})
    with atomic_path(tmp_path / "b.bin") as tmp:
        with open(tmp, "wb") as f:  # a writer that opens the existing temporary file
            f.write(b"1")
    for name in ("a.json", "b.bin"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode


def test_a_failed_write_leaves_nothing(tmp_path, way):
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "c.bin") as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []


def test_a_file_is_replaced_whole_and_folders_come_with_it(tmp_path, way):
    target = tmp_path / "new" / "deeper" / "d.bin"
    for content in (b"first", b"second, longer"):
        with atomic_path(target) as tmp:
            tmp.write_bytes(content[:3])
            with open(tmp, "wb") as f:  # reopened and truncated by a second writer
                f.write(content)
            if way == "anonymous":  # nothing under a name until the file is complete
                assert not (tmp_path / "new").exists() or target.read_bytes() == b"first"
        assert target.read_bytes() == content
        assert [p.name for p in target.parent.iterdir()] == ["d.bin"]  # no hidden name left
        assert target.stat().st_nlink == 1


def test_the_anonymous_file_is_used_on_linux(tmp_path):
    if not hasattr(os, "O_TMPFILE"):
        pytest.skip("no O_TMPFILE on this system")
    with atomic_path(tmp_path / "e.bin") as tmp:
        assert str(tmp).startswith("/proc/self/fd/")
        tmp.write_bytes(b"1")
        assert list(tmp_path.iterdir()) == []  # no name while it is written
