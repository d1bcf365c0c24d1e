"""engine.safe_files: what a file from a stranger may be, each refusal one line naming the file, and no
read that hangs (a FIFO with no writer) or grows without bound (/dev/zero)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from tracelab.engine.safe_files import FileRefused, read_bytes, read_json
from tracelab.errors import user_error_message


def refusal(path: Path | str, **kw: object) -> str:
    with pytest.raises(FileRefused) as e:
        read_json(path, **kw)  # type: ignore[arg-type]
    message = user_error_message(e.value)
    assert message is not None and "\n" not in message and message.startswith(str(path))
    return message


def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "meta.json")
    assert "named pipe" in refusal(tmp_path / "meta.json")


def test_devices_and_directories_are_refused(tmp_path: Path) -> None:
    assert "character device" in refusal("/dev/zero")
    assert "directory" in refusal(tmp_path)


def test_a_symbolic_link_is_refused_only_when_asked(tmp_path: Path) -> None:
    (tmp_path / "real.json").write_text('{"a": 1}')
    (tmp_path / "link.json").symlink_to(tmp_path / "real.json")
    assert read_json(tmp_path / "link.json") == {"a": 1}
    assert "symbolic link" in refusal(tmp_path / "link.json", follow_symlinks=False)


def test_size_cap_and_malformed_json_are_located(tmp_path: Path) -> None:
    (tmp_path / "big.json").write_text("[" + "1," * 1000 + "1]")
    assert "larger than 100 bytes" in refusal(tmp_path / "big.json", max_bytes=100)
    (tmp_path / "bad.json").write_text('{"a":\n [1')
    assert refusal(tmp_path / "bad.json").startswith(f"{tmp_path / 'bad.json'}:2:")
    (tmp_path / "deep.json").write_text("[" * 200_000)
    assert "nested too deeply" in refusal(tmp_path / "deep.json")
    assert read_bytes(tmp_path / "bad.json", 100) == b'{"a":\n [1'
