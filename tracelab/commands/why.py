"""`tracelab why`: the proof tree of an atom's bound at a time in an episode, read from the stored trace;
with --action AGENT, the agent's decision at a step (tracelab/store/agent_why.py)."""
from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.errors import UserError, store_errors
from tracelab.store.reader import open_run, retrying

if TYPE_CHECKING:
    import duckdb


def last_t(con: "duckdb.DuckDBPyConnection", episode: int) -> int:
    """The episode's last timestep: its recorded t_end, else its last trace row's."""
    row = con.execute("SELECT coalesce((SELECT max(t_end) FROM raw.episode_end WHERE episode = $e), "
                      "(SELECT max(t) FROM raw.changes WHERE episode = $e))", {"e": episode}).fetchone()
    if row[0] is None:
        raise KeyError(f"episode {episode} has no trace rows")
    return int(row[0])


def check_at(at: int | None, episode: int, end: int) -> None:
    if at is not None and at > end:
        raise UserError(f"--at {at} is past the end of episode {episode}: its last timestep is t={end}")


def refuse_complement(atom: str) -> None:
    """`why` explains an atom's own bound. A complement `~p(a)` has the bound [1-u,1-l] of p(a)'s [l,u],
    so its explanation is p(a)'s: say so rather than silently dropping the `~`."""
    if atom.lstrip().startswith("~"):
        plain = atom.lstrip()[1:].strip()
        raise UserError(f"why explains an atom's own bound, not a complement: ask `why '{plain}'` "
                        f"(the bound of {atom.strip()} is [1-u,1-l] where [l,u] is the bound of {plain})")


def change_in_pass(changes: list[tuple[int, int]], atom: str, t: int, pass_no: int) -> int:
    """The seq of the atom's last change in `pass_no` of step t, or a UserError naming the passes it has."""
    seqs = [seq for p, seq in changes if p == pass_no]
    if seqs:
        return seqs[-1]
    if not changes:
        raise UserError(f"{atom} did not change at t={t}: without --pass, why explains its bound then")
    passes = sorted({p for p, _ in changes})
    raise UserError(f"{atom} did not change in pass {pass_no} of t={t}; it changed then in pass"
                    f"{'es' if len(passes) > 1 else ''} {', '.join(map(str, passes))}")


def action_explanation(args: argparse.Namespace, agent_of: Callable[[Any], str] | None = None) -> Any:
    """The decision of --action AGENT at --at (required) of --episode, read from the run; `agent_of(con)`:
    the agent instead (why-not's --agent, or its episode's one deciding agent read on the same connection)."""
    if args.at is None:
        raise UserError("--action needs --at STEP: the step whose action to explain")
    from tracelab.store.agent_why import explain_action  # deferred: why of an atom does not read decisions
    with store_errors(), ctrl_c_stops_queries():
        con = open_run(args.run)
        try:
            agent = args.action if agent_of is None else agent_of(con)
            return retrying(lambda: explain_action(con, args.episode, agent, args.at))
        finally:
            con.close()


def run_action(args: argparse.Namespace) -> int:
    e = action_explanation(args)
    from tracelab.store.agent_why import render_action
    print(json.dumps(e.to_dict(), indent=1) if args.json else render_action(e, shlex.quote(str(args.run))))
    return 0


def run(args: argparse.Namespace) -> int:
    if (args.atom is None) == (args.action is None):
        raise UserError("why explains an atom (why RUN ATOM ...) or an agent's action (why RUN --action AGENT "
                        "...): give one of them")
    if args.action is not None:
        return run_action(args)
    refuse_complement(args.atom)
    # deferred: --action reads the decision alone (tracelab.store.agent_why), not the world's trace
    from tracelab.store.coordinates import run_grid
    from tracelab.store.why import episode_at, explain_change_in, explain_in, render_why
    with store_errors(), ctrl_c_stops_queries():
        con = open_run(args.run)
        grid = retrying(lambda: run_grid(con))
        end = last_t(con, args.episode)
        check_at(args.at, args.episode, end)
        at = end if args.at is None else args.at
        # one read of the run's vocabulary and of the episode's rows up to `at`, for the tree and the note
        model, trace = retrying(lambda: episode_at(con, args.episode, at))
        aid = model.parse_atom(args.atom)  # an atom outside the run's vocabulary: its error first
        changes = trace.changes_at(aid, at)
        if args.pass_no is not None:
            seq = change_in_pass(changes, args.atom, at, args.pass_no)
            tree = retrying(lambda: explain_change_in(model, trace, seq, depth=args.depth))
        else:
            tree = retrying(lambda: explain_in(model, trace, aid, at, depth=args.depth))
            if len(changes) > 1:  # the end-of-step bound hides the earlier changes: say how to see them
                earlier = sorted({p for p, _ in changes[:-1]})
                print(f"note: {args.atom} changed {len(changes)} times at t={at} (passes "
                      f"{', '.join(str(p) for p, _ in changes)}); this is its bound at the end of the step; "
                      f"--pass {earlier[0]} explains an earlier change", file=sys.stderr)
    if args.json:
        print(json.dumps({"episode": args.episode, "at": at, "pass": args.pass_no, "tree": tree.to_dict()},
                         indent=1))
    else:
        print(render_why(tree, None if args.pass_no is not None else at, grid))
    return 0
