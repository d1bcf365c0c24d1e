"""PyReason's functional tests (README.md) run as PyReason runs them: from a directory where
`./tests/functional/<graph>.graphml` is found (each test's own temporary directory, holding a link to
this folder, so that files a test writes stay there), with PyReason's `slow` marker registered, and
skipped with the reason when pandas (the DataFrames of filter_and_sort_*, the optional extra
`tracelab[pyreason]`) is not installed."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: PyReason's marker for its slower functional tests")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if importlib.util.find_spec("pandas") is not None:
        return
    skip = pytest.mark.skip(reason="needs pandas (pip install 'tracelab[pyreason]')")
    for item in items:
        if Path(str(item.fspath)).parent == HERE:
            item.add_marker(skip)


@pytest.fixture(autouse=True)
def pyreason_working_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "functional").symlink_to(HERE, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
