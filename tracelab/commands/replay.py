"""`tracelab replay`: traced games of a run as rerun recordings, the rules that fired annotated; a run
without a board (a reasoning run) as its graph, coloured by one predicate (docs/replay.md)."""
from __future__ import annotations

import argparse
import sys
import time

from tracelab.commands._args import non_negative_int, positive_int
from tracelab.errors import store_errors


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="replay traced games (or a reasoning over a graph) in rerun's viewer, "
                                      "with the fired rules annotated")
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--episode", "-e", type=non_negative_int, help="one episode id")
    which.add_argument("--episodes", help="episodes, e.g. 0-9 or 1,4,7-9")
    p.add_argument("--outcome", help="only episodes with this outcome (for red: win, loss, draw, truncated; "
                                     "a reasoning: converged, stopped, failed)")
    p.add_argument("--limit", type=positive_int, help="at most this many episodes")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--save", metavar="FILE.rrd", help="write an .rrd file (the default: replay.rrd)")
    out.add_argument("--serve", action="store_true", help="serve the web viewer on localhost")
    out.add_argument("--spawn", action="store_true", help="open rerun's native viewer")
    p.add_argument("--live", action="store_true",
                   help="follow a run being written: stream each episode (a game, a reasoning) as it ends, "
                        "until the run stops")
    p.add_argument("--port", type=int, default=9876, help="gRPC port for --serve / --spawn (default 9876)")
    p.add_argument("--web-port", type=int, default=9090, help="web viewer port for --serve (default 9090)")
    p.add_argument("--why-depth", type=positive_int, default=6, help="depth of the why-trees (default 6)")
    p.add_argument("--lanes", default="alive,atLoc,health,ammo,action",
                   help="state lanes to draw, comma-separated (default: alive,atLoc,health,ammo,action)")
    p.add_argument("--color-by", metavar="PRED",
                   help="a run without a board: the predicate whose bound colours the nodes (default: the one "
                        "with the most changes over nodes)")
    p.add_argument("--why", metavar="ATOM", action="append", default=[],
                   help="a run without a board: show this atom's why-tree at each step, e.g. "
                        "--why 'exposed(http-tools)' (repeatable)")
    p.add_argument("--open-at", choices=("start", "end"), default="start",
                   help="where the viewer's time cursor starts (default: the first step)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # deferred: loads DuckDB, rerun; every command is imported to build the CLI's parser
    from tracelab.store.reader import open_run, resolve_run
    from tracelab.viewers.replay.outputs import GrpcOutput, SaveOutput
    from tracelab.viewers.replay.recording import ReplayOptions
    from tracelab.viewers.replay.replay import context_of, follow_run, replay_run
    from tracelab.viewers.replay.lanes import parse_lanes
    from tracelab.viewers.replay.select import EpisodeFilter, EpisodeIds, parse_episodes

    with store_errors():
        ids = EpisodeIds.of(args.episode) if args.episode is not None else \
            parse_episodes(args.episodes) if args.episodes else None
        f = EpisodeFilter(ids, args.outcome, args.limit)
        name = resolve_run(args.run).name.removesuffix(".duckdb")
        con = open_run(args.run)
        options = ReplayOptions(why_depth=args.why_depth, lanes=parse_lanes(args.lanes), open_at=args.open_at,
                                color_by=args.color_by, why_atoms=tuple(args.why))
        if args.serve or args.spawn:
            out = GrpcOutput("serve" if args.serve else "spawn", args.port, args.web_port)
        else:
            out = SaveOutput(args.save or "replay.rrd")
        if args.live:
            print(f"following {args.run}: each episode is sent as it ends (Ctrl-C stops)", file=sys.stderr)
            follow_run(con, name, args.run, f, out, options,
                       on_episode=lambda e: print(f"episode {e} sent", file=sys.stderr, flush=True))
        else:
            replay_run(context_of(con, name), f, out, options)
    print(out.describe())
    if args.serve:
        print("serving; Ctrl-C stops", file=sys.stderr)
        _wait_forever()
    return 0


def _wait_forever() -> None:
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
