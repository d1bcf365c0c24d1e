"""Runs from strangers, round two (issues 37 and 43): a run folder's name is a name, never a pattern;
nothing a command writes into a run goes through a link; strings from a run reach the terminal with
their control characters escaped; a repair is all or nothing; a closing hint never fails a command."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from store_helpers import write_walk_run

from tracelab.cli import main
from tracelab.store.seal import seal_run


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_walk_run(tmp_path_factory.mktemp("strangers-runs") / "walk")


def json_rows(argv: list[str], capsys: pytest.CaptureFixture) -> list[dict]:
    assert main([*argv, "--format", "json"]) == 0
    return json.loads(capsys.readouterr().out)


# ---- 43.2: a run folder's name is read as a name ----------------------------------------------------------

@pytest.mark.parametrize("name", ["r*", "r?z", "r[!a]z", "r{zz,a}"])
@pytest.mark.parametrize("sealed", [False, True], ids=["live", "sealed"])
def test_a_run_named_like_a_pattern_reads_only_its_own_parts(walk: Path, tmp_path: Path, name: str,
                                                            sealed: bool, capsys: pytest.CaptureFixture) -> None:
    """`r*` beside `rzz` (and the other glob syntaxes beside a run they would match): each run reads
    its own three episodes, alone or as a folder of runs, live or sealed."""
    folder = tmp_path / "runs"
    folder.mkdir()
    for n in (name, "rzz", "rzzz"):
        shutil.copytree(walk, folder / n)
    if sealed:  # DuckDB cannot create a file under a '?': sealed elsewhere, then moved in
        shutil.rmtree(folder / name)
        shutil.copytree(walk, tmp_path / "plain")
        seal_run(tmp_path / "plain")
        (tmp_path / "plain").rename(folder / name)
    alone = json_rows(["sql", str(folder / name), "SELECT episode FROM episodes ORDER BY episode"], capsys)
    assert [r["episode"] for r in alone] == [10, 11, 12]
    several = json_rows(["sql", str(folder), "SELECT run, count(*) AS n FROM episodes GROUP BY run ORDER BY run"],
                        capsys)
    assert {r["run"]: r["n"] for r in several} == {name: 3, "rzz": 3, "rzzz": 3}


def test_a_fact_table_named_like_a_pattern_is_that_one_file(tmp_path: Path) -> None:
    from tracelab.engine.facttable import load_fact_table
    (tmp_path / "f*.csv").write_text("atom\nred(a)\n")
    (tmp_path / "fzz.csv").write_text("atom\nblue(b)\nblue(c)\n")
    graph = load_fact_table(tmp_path / "f*.csv")
    assert graph.n_facts == 1


@pytest.mark.parametrize("name", ["r*", "r[z]z"])
def test_seal_reads_only_the_parts_of_a_run_named_like_a_pattern(walk: Path, tmp_path: Path, name: str,
                                                                 capsys: pytest.CaptureFixture) -> None:
    for n in (name, "rzz"):
        shutil.copytree(walk, tmp_path / n)
    seal_run(tmp_path / name)
    rows = json_rows(["sql", str(tmp_path / name), "SELECT count(*) AS n FROM episodes"], capsys)
    assert rows == [{"n": 3}]


def test_seal_refuses_a_path_with_a_question_mark_in_one_line(walk: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture) -> None:
    shutil.copytree(walk, tmp_path / "r?z")
    assert main(["seal", str(tmp_path / "r?z")]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "'?'" in err and "Traceback" not in err
