"""The SQL console's history, kept between sessions in a small file of the user's state folder
($XDG_STATE_HOME/tracelab/sql_history, else ~/.local/state/tracelab/sql_history): a JSON list of
statements, oldest first, capped at HISTORY_CAP.

The file is the user's own, but another program (or a stranger's archive unpacked there) may have put
anything at that path: it is read with safe_files (a regular file, never through a symbolic link,
bounded), and anything malformed is ignored as if there were no history. It is written whole to a new
file beside it (created 0600 with O_NOFOLLOW) that then replaces it, so a crash never leaves half a
history; a symbolic link or anything else that is not a regular file at the path is left alone."""
from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from tracelab.engine.safe_files import FileRefused, read_json, replacing

HISTORY_CAP = 500              # statements kept
MAX_STATEMENT_CHARS = 16_384   # a longer statement (a pasted dump) is not kept
HISTORY_FILE_CAP = 2 << 20     # bytes read at most (500 x 16 KiB would be 8 MiB: such a file is not ours)


def history_path() -> Path:
    base = os.environ.get("XDG_STATE_HOME") or os.path.join(os.path.expanduser("~"), ".local", "state")
    return Path(base) / "tracelab" / "sql_history"


def load_history(path: Path) -> list[str]:
    """The statements in the history file, oldest first; [] if there is none or it is not one."""
    try:
        data = read_json(path, HISTORY_FILE_CAP, what="SQL history", follow_symlinks=False)
    except (OSError, FileRefused):
        return []
    if not isinstance(data, list) or not all(isinstance(q, str) for q in data):
        return []
    return data[-HISTORY_CAP:]


def add_to_history(history: list[str], sql: str) -> list[str]:
    """`history` with `sql` appended (not twice in a row), capped."""
    if len(sql) > MAX_STATEMENT_CHARS or (history and history[-1] == sql):
        return history
    return [*history, sql][-HISTORY_CAP:]


def save_history(path: Path, history: list[str]) -> None:
    """Replace the history file with `history`. OSError if it cannot be written (a read-only home, a
    symbolic link or a directory at the path)."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            raise OSError(f"{path}: not a regular file; the history is not saved there")
    except FileNotFoundError:
        pass
    with replacing(path, 0o600) as f:
        f.write(json.dumps(history[-HISTORY_CAP:], indent=0).encode())
