"""`tracelab rewards`: each recorded episode's return by reward term, or re-scored under other term values
without re-simulating (tracelab/store/reward_rescore.py)."""
from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.errors import store_errors
from tracelab.store.reader import open_run, retrying
from tracelab.store.reward_rescore import rescore

if TYPE_CHECKING:
    from tracelab.store.reward_rescore import Rescored


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def render(r: "Rescored") -> str:
    """The table: a row per episode and agent, then the total over them."""
    if r.sets:
        head = ["episode", "agent", "return", "re-scored", "change"]
        body = [[str(x["episode"]), x["agent"], _fmt(x["return"]), _fmt(x["rescored"]),
                 _fmt(x["rescored"] - x["return"])] for x in r.rows]
        ret, new = sum(x["return"] for x in r.rows), sum(x["rescored"] for x in r.rows)
        body.append(["total", "", _fmt(ret), _fmt(new), _fmt(new - ret)])
    else:
        head = ["episode", "agent", *r.terms, "return"]
        body = [[str(x["episode"]), x["agent"], *(_fmt(x["by_term"].get(t, 0.0)) for t in r.terms),
                 _fmt(x["return"])] for x in r.rows]
        body.append(["total", "", *(_fmt(sum(x["by_term"].get(t, 0.0) for x in r.rows)) for t in r.terms),
                     _fmt(sum(x["return"] for x in r.rows))])
    widths = [max(len(row[i]) for row in (head, *body)) for i in range(len(head))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip() for row in (head, *body)]
    if r.sets:
        lines.insert(0, "re-scored with " + ", ".join(f"{t}={_fmt(n)} (was {_fmt(o)})" for t, (o, n) in r.sets.items()))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    with store_errors(), ctrl_c_stops_queries():
        con = open_run(args.run)
        try:
            result = retrying(lambda: rescore(con, args.sets, args.episode))
        finally:
            con.close()
    if args.json:
        print(json.dumps(result.to_dict(), indent=1))
    else:
        print(render(result))
        for note in result.notes:
            print(f"note: {note}", file=sys.stderr)
    return 0
