"""Atomic writes leave either the old file or the whole new one, with the permissions a user expects."""

from __future__ import annotations

import os
import stat

import pytest

from lirm.engine.io.atomic_files import atomic_write, atomic_write_bytes, atomic_write_json


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_a_new_file_gets_the_permissions_a_plain_write_would_give(tmp_path):
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    new = atomic_write_json(tmp_path / "out" / "new.json", {"a": 1})
    assert new.read_text().strip().startswith("{") and _mode(new) == _mode(plain)  # not the temporary file's 0600
    assert not [p for p in new.parent.iterdir() if p.name.startswith(".")]  # no temporary file left


def test_a_replaced_file_keeps_its_permissions_and_a_failed_write_keeps_the_old_file(tmp_path):
    target = tmp_path / "asset.glb"
    target.write_bytes(b"old")
    os.chmod(target, 0o640)
    atomic_write_bytes(target, b"new")
    assert target.read_bytes() == b"new" and _mode(target) == 0o640

    def broken(tmp):
        tmp.write_bytes(b"half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        atomic_write(target, broken)
    assert target.read_bytes() == b"new" and [p.name for p in tmp_path.iterdir()] == ["asset.glb"]
