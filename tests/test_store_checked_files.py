"""A sealed file whose catalog passed is recorded by its identity, and its catalog entries are not read
again (tracelab.store.checked_files): the record never lets a changed file, or a record another user
could have planted, skip the check."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import duckdb
import pytest

from tracelab.store import checked_files
from tracelab.store.reader import open_run
from tracelab.store.sealed_catalog import SealedFileRefused, checker_version

SAMPLE = Path(__file__).resolve().parents[1] / "sample_runs" / "advanced"
MACRO = "CREATE MACRO main.evil(x) AS x || 'ran'"


@pytest.fixture
def records(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv(checked_files.CACHE_ENV, str(tmp_path / "cache"))
    return tmp_path / "cache" / checked_files.FOLDER


def copy_run(tmp_path: Path, name: str = "run") -> Path:
    return Path(shutil.copytree(SAMPLE, tmp_path / name))


def add_macro(run: Path) -> None:
    con = duckdb.connect(str(run / "run.duckdb"))
    con.execute(MACRO)
    con.close()


def opens(run: Path) -> bool:
    open_run(run).close()
    return True


def test_a_checked_file_changed_afterwards_is_checked_again(tmp_path: Path, records: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(checked_files, "RACY_S", 0.0)   # record the fresh copy at once
    run = copy_run(tmp_path)
    assert opens(run) and len(os.listdir(records)) == 1
    add_macro(run)   # in place: same path, same inode
    with pytest.raises(SealedFileRefused, match="holds a macro main.evil"):
        open_run(run)
    assert len(os.listdir(records)) == 1   # the refused file is not recorded


def test_a_file_changed_within_the_racy_window_is_not_recorded(tmp_path: Path, records: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(checked_files, "RACY_S", 3600.0)
    run = copy_run(tmp_path)
    assert opens(run) and not records.exists()


def test_only_a_record_in_this_users_private_folder_skips_the_entries(tmp_path: Path, records: Path) -> None:
    """A record of a tampered file (as if the file had passed): trusted in the private folder only, where
    whoever writes it can run code as the user anyway; in a folder others may write, ignored."""
    run = copy_run(tmp_path)
    add_macro(run)
    records.mkdir(parents=True, mode=0o700)
    identity = checked_files.file_identity((run / "run.duckdb").resolve())
    planted = checked_files._record(identity, checker_version())
    planted.touch()
    os.chmod(records, 0o777)
    with pytest.raises(SealedFileRefused, match="holds a macro main.evil"):
        open_run(run)
    os.chmod(records, 0o700)
    assert opens(run)
    planted.unlink()
    with pytest.raises(SealedFileRefused, match="holds a macro main.evil"):
        open_run(run)


def test_the_columns_are_checked_every_time(tmp_path: Path, records: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A recorded file's columns are still read and checked (they decide the views)."""
    run = copy_run(tmp_path)
    con = duckdb.connect(str(run / "run.duckdb"))
    con.execute("ALTER TABLE raw.steps ADD COLUMN extra INTEGER")
    con.close()
    records.mkdir(parents=True, mode=0o700)
    checked_files._record(checked_files.file_identity((run / "run.duckdb").resolve()), checker_version()).touch()
    with pytest.raises(SealedFileRefused, match="raw.steps has a column extra"):
        open_run(run)
