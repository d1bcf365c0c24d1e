"""`tracelab why-not`: why a rule did not fire for a grounding at a time: its first body clause that failed."""
from __future__ import annotations

import argparse
import json
from typing import Any

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.commands.why import action_explanation, check_at, last_t
from tracelab.errors import UserError, store_errors
from tracelab.store.reader import open_run, retrying


def run(args: argparse.Namespace) -> int:
    if (args.rule is None) == (args.action is None):
        raise UserError("why-not asks about a rule (--rule NAME) or an agent's action (--action NAME): give one")
    if args.action is not None:
        return run_action(args)
    from tracelab.store.why import parse_bindings, render_why_not, why_not  # deferred: --action reads none of it
    with store_errors(), ctrl_c_stops_queries():
        con, bindings = open_run(args.run), parse_bindings(args.grounding)
        check_at(args.at, args.episode, last_t(con, args.episode))
        result = retrying(lambda: why_not(con, args.episode, args.rule, bindings, args.at))
    print(json.dumps(result.to_dict(), indent=1) if args.json else render_why_not(result))
    return 0


def run_action(args: argparse.Namespace) -> int:
    if args.grounding:
        raise UserError("--grounding goes with --rule, not --action")
    name = args.action

    def the_one_agent(con: Any) -> str:
        """--agent left out: the episode's one deciding agent (read on the connection that reads its decision)."""
        agents = [a for (a,) in con.execute("SELECT DISTINCT agent FROM raw.decisions WHERE episode = ? "
                                            "ORDER BY agent", [args.episode]).fetchall()]
        if len(agents) != 1:
            raise UserError(f"--agent: episode {args.episode} has {len(agents)} deciding agents"
                            + (f" ({', '.join(agents)})" if agents else "") + "; name one")
        return agents[0]

    e = action_explanation(args, the_one_agent if args.agent is None else lambda con: args.agent)
    from tracelab.store.agent_why import render_why_not_action, why_not_action  # deferred: --action only
    with store_errors():
        result = why_not_action(e, name)
    print(json.dumps(result.to_dict(), indent=1) if args.json else render_why_not_action(result))
    return 0
