"""`tracelab diff`: what two episodes were given (rules, facts), where they ended (final bounds) and where
they first diverge (trace and actions), in one run or across runs.

    tracelab diff RUN A B                 episodes A and B of RUN
    tracelab diff RUN_A:EP RUN_B:EP       episode EP of RUN_A against episode EP of RUN_B
    tracelab diff RUN_A RUN_B             two runs of one episode each (two reasonings, say), or a what-if
                                          branch (tracelab whatif) and its origin: the episode it branched off
"""
from __future__ import annotations

import argparse
import json

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.errors import UserError, store_errors
from tracelab.store.branch_origin import origin_episode
from tracelab.store.diff import first_divergence, render_divergence
from tracelab.store.reader import open_run, resolve_run, retrying


def _episode(text: str, what: str) -> int:
    try:
        e = int(text)
    except ValueError:
        raise UserError(f"{what}: expected an episode number, got {text!r}") from None
    if e < 0:
        raise UserError(f"{what}: an episode number is 0 or more, got {e}")
    return e


def _run_and_episode(text: str) -> tuple[str, int]:
    run, colon, ep = text.rpartition(":")
    if not colon or not run:
        raise UserError(f"cannot read {text!r}: write RUN:EPISODE, e.g. runs/play-base:0")
    return run, _episode(ep, text)


def _side(text: str) -> tuple[str, int | None]:
    """RUN:EP, or a RUN alone (episode None: its only one)."""
    try:
        return _run_and_episode(text)
    except UserError as bad_episode:
        try:
            resolve_run(text)
        except FileNotFoundError:
            if _is_run(text.rpartition(":")[0]):
                raise bad_episode from None  # RUN:x of a real run: say what is wrong with x
            raise UserError(f"cannot read {text!r}: write RUN:EPISODE, e.g. runs/play-base:0, or name a "
                            "run of one episode") from None
        return text, None


def _is_run(text: str) -> bool:
    try:
        resolve_run(text)
    except FileNotFoundError:
        return False
    return bool(text)


def parse_sides(sides: list[str]) -> tuple[tuple[str, int | None], tuple[str, int | None]]:
    """((run, episode), (run, episode)) from `RUN A B` or `RUN_A[:EP] RUN_B[:EP]` (None: the run's only
    episode)."""
    if len(sides) == 3:
        return (sides[0], _episode(sides[1], "A")), (sides[0], _episode(sides[2], "B"))
    if len(sides) == 2:
        return _side(sides[0]), _side(sides[1])
    raise UserError(f"diff takes RUN A B or RUN_A[:EP] RUN_B[:EP], got {len(sides)} argument(s)")


def only_episode(con: object, run: str) -> int:
    """The episode of a run of one episode; else a UserError listing its episodes."""
    episodes = [e for (e,) in con.execute(  # type: ignore[attr-defined]
        "SELECT episode FROM (SELECT episode FROM raw.episode_begin UNION SELECT DISTINCT episode "
        "FROM raw.changes) ORDER BY 1 LIMIT 21").fetchall()]
    if len(episodes) != 1:
        shown = ", ".join(map(str, episodes[:20])) + (", ..." if len(episodes) > 20 else "")
        raise UserError(f"{run} has {'no episodes' if not episodes else 'episodes ' + shown}: name one, "
                        f"{run}:EPISODE")
    return int(episodes[0])


def _is_one_run(run_a: str, run_b: str) -> bool:
    return resolve_run(run_a).resolve() == resolve_run(run_b).resolve()


def _episode_of(con: object, run: str, other: object) -> int:
    """The episode of `run` to compare when none is named: the one the other run branched off when it is
    a what-if branch of `run` (tracelab whatif), else its only one."""
    e = origin_episode(other, resolve_run(run))  # type: ignore[arg-type]
    return only_episode(con, run) if e is None else e


def run(args: argparse.Namespace) -> int:
    (run_a, a), (run_b, b) = parse_sides(args.sides)
    with store_errors(), ctrl_c_stops_queries():
        con_a = open_run(run_a)
        if _is_one_run(run_a, run_b):
            a = only_episode(con_a, run_a) if a is None else a
            b = only_episode(con_a, run_b) if b is None else b
            d = retrying(lambda: first_divergence(con_a, a, b))
        else:
            con_b = open_run(run_b)
            a = _episode_of(con_a, run_a, con_b) if a is None else a
            b = _episode_of(con_b, run_b, con_a) if b is None else b
            d = retrying(lambda: first_divergence(con_a, a, b, con_b, run_names=(run_a, run_b)))
    print(json.dumps(d.to_dict(), indent=1, default=str) if args.json else render_divergence(d))
    return 0
