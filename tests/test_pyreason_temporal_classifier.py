"""PyReason's TemporalLogicIntegratedClassifier (examples/temporal_classifier_ex.py): a classifier that
polls its model from a thread and reasons on. The polls are driven here by a ManualClock (a timedelta
interval) or by the program's own time (an int interval): no test waits on the wall clock; each waits
for the poller's count (wait_for_checks, a generous ceiling)."""
from __future__ import annotations

from collections.abc import Iterator
from datetime import timedelta

import pytest

import tracelab.pyreason as pr

torch = pytest.importorskip("torch")
pytest.importorskip("pandas")

from tracelab.pyreason.temporal_classifier import ManualClock  # noqa: E402 (after torch's skip)

GAP = torch.tensor([[0.0, 4.0]])  # an input the identity model classifies "gap" (softmax 0.98)
GOOD = torch.tensor([[4.0, 0.0]])
OPTIONS = pr.ModelInterfaceOptions(threshold=0.5, set_lower_bound=True, set_upper_bound=False, snap_value=1.0)


@pytest.fixture(autouse=True)
def fresh() -> Iterator[None]:
    pr.reset()
    pr.reset_rules()
    pr.reset_settings()
    pr.api._program.last = pr.api._program.reasoning = None  # a poller starts from the first reasoning it sees
    yield
    pr.reset()
    pr.reset_rules()


def weld_rules() -> None:
    """examples/temporal_classifier_ex.py's rules."""
    pr.add_rule(pr.Rule("repairing(weld_object) <-1 gap(weld_object)", "repair attempted rule"))
    pr.add_rule(pr.Rule("defective(weld_object) <-1 gap(weld_object), repairing(weld_object)", "defective rule"))


def checker(interval: timedelta | int, inputs: list[torch.Tensor], clock: ManualClock | None = None,
            condition: str | None = "gap") -> pr.TemporalLogicIntegratedClassifier:
    return pr.TemporalLogicIntegratedClassifier(torch.nn.Identity(), ["good", "gap"], identifier="weld_object",
                                                interface_options=OPTIONS, poll_interval=interval,
                                                poll_condition=condition, input_fn=lambda: inputs.pop(0),
                                                clock=clock)


def fact_rows(interpretation: pr.Interpretation) -> list[tuple[int, str, str]]:
    nodes, _ = pr.get_rule_trace(interpretation)
    return [(int(t), label, bound) for t, label, bound, by in
            nodes[["Time", "Label", "New Bound", "Triggered By"]].values.tolist() if by == "Fact"]


def test_a_timedelta_poll_runs_when_the_clock_reaches_it_and_reasons_on_from_the_next_step() -> None:
    clock = ManualClock()
    weld = checker(timedelta(seconds=0.5), [GAP], clock)
    try:
        weld_rules()
        _, _, facts = weld(GOOD, 0, 0)
        for f in facts:
            pr.add_fact(f)
        pr.reason(timesteps=1)  # converges at t = 0 (nothing pending)
        clock.advance(0.5)  # due: the condition gap(weld_object) does not hold, no reasoning
        assert weld.wait_for_checks(1, timeout=120) and (weld.checks, weld.polls) == (1, 0)
        assert pr.get_time() == 1
        # the script's own step: the model sees a gap at t = 1 (a fact for t = 1, 2)
        _, _, facts = weld(GAP, pr.get_time(), pr.get_time() + 1)
        for f in facts:
            pr.add_fact(f)
        pr.reason(timesteps=2, again=True, restart=False)  # t = 1, 2
        assert pr.get_interpretation().query(pr.Query("repairing(weld_object)"))
        before = pr.get_interpretation().time
        clock.advance(0.2)
        assert weld.checks == 1  # not due before 1.0 s
        clock.advance(0.3)
        assert weld.wait_for_checks(2, timeout=120) and (weld.checks, weld.polls) == (2, 1)
    finally:
        weld.stop()
    interpretation = pr.get_interpretation()
    # the poll's facts land at the step after the last one, as PyReason's poller puts them
    assert (before + 1, "gap", "[1.0,1.0]") in fact_rows(interpretation)
    assert interpretation.query(pr.Query("defective(weld_object)"))
    assert interpretation.time > before + 1  # again with timesteps=-1: until the delayed firings have landed


def test_an_int_poll_waits_for_the_programs_time() -> None:
    weld = checker(1, [GAP, GOOD])
    try:
        weld_rules()
        _, _, facts = weld(GAP, 0, 3)
        for f in facts:
            pr.add_fact(f)
        pr.reason(timesteps=1)  # t = 0, 1: the poller's first poll is due at t = 3
        assert weld.checks == 0
        pr.reason(timesteps=2, again=True)  # t = 2, 3: gap holds at t = 3, the poll reasons on
        assert weld.wait_for_checks(2, timeout=120)
    finally:
        weld.stop()
    # the first check (t = 3, gap holds) reasoned on until convergence (t = 4); the second (t = 4) found no
    # gap. Its facts are at the current step, t = 3, already reasoned: as in PyReason (restart=False reads
    # them as absolute) they never apply
    assert (weld.checks, weld.polls, pr.get_interpretation().time) == (2, 1, 4)


def test_settings_set_on_pyreasons_settings_class_are_the_settings() -> None:
    # examples/temporal_classifier_ex.py: `from pyreason.pyreason import _Settings as Settings`,
    # `settings = Settings; settings.atom_trace = True` sets the setting in PyReason
    settings = pr._Settings
    settings.persistent = True
    assert pr.settings.persistent is True and settings.persistent is True
    with pytest.raises(TypeError):
        settings.persistent = 3


def test_a_bad_poll_interval_is_refused() -> None:
    with pytest.raises(TypeError, match="poll_interval"):
        checker(0.5, [GAP])  # type: ignore[arg-type]
