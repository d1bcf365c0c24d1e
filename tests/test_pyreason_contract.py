"""The API's contract as PyReason's own tests/api_tests judge it (issue 41, defect 6): with
raise_errors=False the file loaders warn and skip a bad row (a bad option: warn, its default), with
raise_errors=True a bad row or a name a file repeats is a ValueError, malformed JSON a ValueError,
update_mode takes any str, get_rules() is None without rules. The rows are PyReason's
tests/api_tests/test_files (example_facts.csv, example_rules.csv) cut to one of each kind."""
from __future__ import annotations

import warnings
from pathlib import Path

import pytest

import tracelab.pyreason as pr

FACTS_CSV = """fact_text,name,start_time,end_time,static
Viewed(Zach),seen-fact-zach,0,3,False
"HaveAccess(Zach,TextMessage)",access-zach,0,5,True
,empty-fact-text,0,3,False
InvalidSyntax,bad-syntax,0,3,False
Viewed(BadStartTime),bad-start,abc,5,False
Viewed(BadEndTime),bad-end,0,xyz,False
Viewed(BadStaticValue),bad-static,0,5,invalid
"""
RULES_CSV = """rule_text,name,infer_edges,set_static
"friend(A, B) <- knows(A, B)",friendship-rule,False,False
,empty-rule-text,False,False
InvalidRuleSyntax,bad-syntax,False,False
"friend(A, B) <- knows(A, B)",bad-infer,invalid,False
"""


@pytest.fixture(autouse=True)
def fresh() -> None:
    pr.reset()
    pr.reset_rules()
    pr.reset_settings()


def loaded_with_warnings(load, path: Path) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load(str(path), raise_errors=False)
    assert all(issubclass(w.category, UserWarning) for w in caught)
    return [str(w.message) for w in caught]


def test_fact_loaders_warn_skip_bad_rows_and_default_bad_options(tmp_path: Path) -> None:
    path = tmp_path / "facts.csv"
    path.write_text(FACTS_CSV)
    messages = loaded_with_warnings(pr.add_fact_from_csv, path)
    for words in ("Missing required 'fact_text'", "Failed to parse fact", "Invalid start_time", "Invalid end_time",
                  "Invalid static value"):
        assert sum(words in m for m in messages) == 1, (words, messages)
    assert all(str(path) in m for m in messages)  # located
    facts = {f.name: f for f in pr.api._program.facts}
    # the rows that parse are kept; a bad option takes PyReason's default (0, 0, False)
    assert sorted(facts) == ["access-zach", "bad-end", "bad-start", "bad-static", "seen-fact-zach"]
    assert (facts["bad-start"].start_time, facts["bad-end"].end_time, facts["bad-static"].static) == (0, 0, False)


def test_rule_loaders_warn_and_skip_bad_rows(tmp_path: Path) -> None:
    path = tmp_path / "rules.csv"
    path.write_text(RULES_CSV)
    messages = loaded_with_warnings(pr.add_rule_from_csv, path)
    for words in ("Missing required 'rule_text'", "Failed to parse rule", "Invalid infer_edges value"):
        assert sum(words in m for m in messages) == 1, (words, messages)
    assert [r.get_rule_name() for r in pr.get_rules()] == ["friendship-rule", "bad-infer"]
    text = tmp_path / "rules.txt"
    text.write_text("popular(x) <- friend(x,y)\nnot a rule\nsad(x) <- lonely(x)\n")
    pr.reset_rules()
    with pytest.warns(UserWarning, match="Failed to parse rule"):
        pr.add_rules_from_file(str(text))  # PyReason's default here is raise_errors=False
    assert [r.get_rule_name() for r in pr.get_rules()] == ["rule_0", "rule_2"]  # named by line, as PyReason
    pr.reset_rules()
    with pytest.raises(ValueError, match="Failed to parse rule"):
        pr.add_rules_from_file(str(text), raise_errors=True)


@pytest.mark.parametrize("load, ext, text", [
    (pr.add_fact_from_csv, "csv", "Viewed(Alice),duplicate-name\nViewed(Bob),duplicate-name\n"),
    (pr.add_fact_from_json, "json", '[{"fact_text": "Viewed(Alice)", "name": "duplicate-name"},'
                                    ' {"fact_text": "Viewed(Bob)", "name": "duplicate-name"}]'),
    (pr.add_rule_from_csv, "csv", '"a(x) <- b(x)",duplicate-name\n"c(x) <- b(x)",duplicate-name\n'),
    (pr.add_rule_from_json, "json", '[{"rule_text": "a(x) <- b(x)", "name": "duplicate-name"},'
                                    ' {"rule_text": "c(x) <- b(x)", "name": "duplicate-name"}]'),
], ids=["fact-csv", "fact-json", "rule-csv", "rule-json"])
def test_a_name_a_file_repeats_is_refused_or_warned(tmp_path: Path, load, ext: str, text: str) -> None:
    path = tmp_path / f"items.{ext}"
    path.write_text(text)
    with pytest.raises(ValueError, match="duplicate"):
        load(str(path), raise_errors=True)
    with pytest.warns(UserWarning, match="duplicate"):
        load(str(path), raise_errors=False)


def test_malformed_json_and_a_json_that_is_no_array_are_value_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('[{"fact_text": "Viewed(Alice)"')
    with pytest.raises(ValueError, match="Invalid JSON format"):
        pr.add_fact_from_json(str(bad))
    bad.write_text('{"rule_text": "a(x) <- b(x)"}')
    with pytest.raises(ValueError, match="must contain an array"):
        pr.add_rule_from_json(str(bad))
    bad.write_text("[]")
    with pytest.warns(UserWarning, match="contains an empty array"):
        pr.add_fact_from_json(str(bad))


def test_update_mode_and_get_rules_as_pyreason() -> None:
    assert pr.get_rules() is None
    pr.settings.update_mode = "parallel"  # PyReason's own settings test: any str; only 'override' overrides
    assert pr.settings.update_mode == "parallel"
    with pytest.raises(TypeError, match="value has to be a str"):
        pr.settings.update_mode = 1
    with pytest.raises(TypeError, match="value has to be a bool"):
        pr.settings.verbose = "yes"
    pr.add_rule(pr.Rule("a(x) <- b(x)", "r"))
    assert [r.get_rule_name() for r in pr.get_rules()] == ["r"]
