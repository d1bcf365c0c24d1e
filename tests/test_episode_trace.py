"""An episode's rows are searched alike whether they were read as Python lists (a small episode: no numpy
import) or as numpy arrays (past store.episode.PYTHON_ROWS): the why searches give the same answers; and
an atom written as the store writes it is read as the engine's parser reads it."""
from __future__ import annotations

from pathlib import Path

import pytest

from tracelab.engine.parser import parse_literal
from tracelab.store import episode
from tracelab.store.model import RunModel
from tracelab.store.reader import open_run
from tracelab.store.why import explain, why_not

RUN = Path(__file__).resolve().parents[1] / "sample_runs" / "advanced"


def _answers() -> list[dict]:
    con = open_run(RUN)
    try:
        return [explain(con, 0, "captured(blue)", at=21, depth=4).to_dict(),
                explain(con, 0, "atLoc(red-agent-1,c6_6)", at=9, depth=3).to_dict(),
                why_not(con, 0, "snap_at", {}, 21).to_dict()]
    finally:
        con.close()


def test_lists_and_numpy_arrays_give_the_same_why(monkeypatch: pytest.MonkeyPatch) -> None:
    as_lists = _answers()
    read = []
    original = episode._read_columns
    monkeypatch.setattr(episode, "_read_columns", lambda *a: read.append(c := original(*a)) or c)
    monkeypatch.setattr(episode, "PYTHON_ROWS", 0)  # every episode as numpy arrays
    assert _answers() == as_lists
    assert read and all(type(c["seq"]).__name__ == "ndarray" for c in read)  # the numpy path ran
    assert as_lists[0]["children"] and as_lists[0]["cause"]["bindings"]  # the answers say something


def test_a_plain_atom_is_read_as_the_parser_reads_it() -> None:
    con = open_run(RUN)
    try:
        model = RunModel(con)
        for text in ("captured(blue)", "atLoc(red-agent-1,c6_6)", " atLoc( red-agent-1 , c6_6 ) "):
            lit = parse_literal(text)
            assert model.parse_atom(text) == model.find_atom(lit.pred, tuple(t.name for t in lit.args))
        with pytest.raises(ValueError, match="not ground"):  # a variable: the parser's path, its message
            model.parse_atom("atLoc(A,c6_6)")
    finally:
        con.close()
