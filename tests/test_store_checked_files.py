"""A sealed file whose catalog passed is recorded by its identity, with its stored columns, and its catalog
is not read again (tracelab.store.checked_files): the record never lets a changed file, or a record another user
could have planted, skip the check."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import duckdb
import pytest

from tracelab.store import checked_files, sealed_catalog
from tracelab.store.reader import open_run
from tracelab.store.schema import STORED_COLUMNS
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


def test_a_recorded_files_columns_are_read_from_its_record(tmp_path: Path, records: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """The record holds the stored columns the check found (what the views are made of): opening the same
    file again reads none of its catalog, and answers as before."""
    monkeypatch.setattr(checked_files, "RACY_S", 0.0)
    run = copy_run(tmp_path)
    con = open_run(run)
    first = con.execute("SELECT count(*), sum(reward) FROM steps").fetchall()
    con.close()
    (record,) = records.iterdir()
    recorded = json.loads(record.read_text())
    assert set(recorded) == set(STORED_COLUMNS) and "reward" in recorded["steps"]

    def catalog_read(*args: object, **kwargs: object) -> None:
        raise AssertionError("the catalog was read again")
    monkeypatch.setattr(sealed_catalog, "read_sealed_catalogs", catalog_read)
    con = open_run(run)
    assert con.execute("SELECT count(*), sum(reward) FROM steps").fetchall() == first
    con.close()


def test_a_record_naming_a_column_not_in_the_schema_is_not_used(tmp_path: Path, records: Path) -> None:
    run = copy_run(tmp_path)
    con = duckdb.connect(str(run / "run.duckdb"))
    con.execute("ALTER TABLE raw.steps ADD COLUMN extra INTEGER")
    con.close()
    records.mkdir(parents=True, mode=0o700)
    planted = checked_files._record(checked_files.file_identity((run / "run.duckdb").resolve()), checker_version())
    planted.write_text(json.dumps({t: [*cols, "extra"] for t, cols in STORED_COLUMNS.items()}))
    with pytest.raises(SealedFileRefused, match="raw.steps has a column extra"):
        open_run(run)
