"""Export a table on screen (an Arrow table) to CSV or Parquet: a small dialog asks for the file (a new
name in the current folder by default; the suffix says the format) and never replaces a file without
saying so first (Enter again on the same name replaces it)."""
from __future__ import annotations

from pathlib import Path

import pyarrow as pa
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Label, Static

from tracelab.errors import user_error_message
from tracelab.store.table_files import EXPORT_FORMATS, write_table_file


def free_name(stem: str, suffix: str = ".csv", folder: Path | None = None) -> Path:
    """`stem.csv` in `folder` (default: the current one), or `stem-2.csv`, ... the first that is free."""
    folder = folder or Path.cwd()
    path, n = folder / f"{stem}{suffix}", 1
    while path.exists() or path.is_symlink():
        n += 1
        path = folder / f"{stem}-{n}{suffix}"
    return path


class ExportDialog(ModalScreen[Path | None]):
    """Ask for a file and write `table` to it; dismissed with the path written (None: closed)."""
    BINDINGS = [Binding("escape", "dismiss(None)", "close")]

    def __init__(self, table: pa.Table, default: Path, what: str = "result") -> None:
        super().__init__()
        self.table = table
        self.default = default
        self.what = what
        self.replace_ok: Path | None = None   # the existing file the user was told about
        self.rows_written: int | None = None

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(f"export the {self.what} ({self.table.num_rows:,} rows) to a file: "
                        f"{' or '.join(sorted(set(EXPORT_FORMATS)))} · Enter writes · Esc closes")
            yield Input(value=str(self.default), id="export-path")
            yield Static("", id="export-message")

    def on_mount(self) -> None:
        self.query_one(Input).focus()

    def _say(self, text: str, style: str = "bold") -> None:
        self.query_one("#export-message", Static).update(Text(text, style=style))

    def on_input_submitted(self, event: Input.Submitted) -> None:
        text = event.value.strip()
        if not text:
            return
        path = Path(text).expanduser()
        if path.suffix.lower() not in EXPORT_FORMATS:
            self._say(f"{path}: end the name in .csv or .parquet (it says which format to write)", "red")
            return
        if path.is_dir():
            self._say(f"{path}: is a folder; give a file name", "red")
            return
        if (path.exists() or path.is_symlink()) and self.replace_ok != path:
            self.replace_ok = path
            self._say(f"{path} exists: Enter again replaces it, or change the name", "yellow")
            return
        self._say(f"writing {path}…", "italic")
        self.run_worker(lambda: self._write(path), thread=True, group="export", exclusive=True,
                        exit_on_error=False)

    def _write(self, path: Path) -> None:
        try:
            n = write_table_file(self.table, path)
        except Exception as e:  # noqa: BLE001 - shown in the dialog: the user may fix the name and retry
            self.app.call_from_thread(self._say, user_error_message(e) or str(e), "red")
            return
        self.rows_written = n
        self.app.call_from_thread(self.dismiss, path)
