"""`tracelab replay`: traced games of a run as rerun recordings, the rules that fired annotated; a run
without a board (a reasoning run) as its graph, coloured by one predicate (docs/replay.md)."""
from __future__ import annotations

import argparse
import sys
import time

from tracelab.errors import store_errors
from tracelab.store.reader import open_run, resolve_run
from tracelab.viewers.replay.outputs import GrpcOutput, SaveOutput
from tracelab.viewers.replay.recording import ReplayOptions
from tracelab.viewers.replay.replay import context_of, follow_run, replay_run
from tracelab.viewers.replay.lanes import parse_lanes
from tracelab.viewers.replay.select import EpisodeFilter, EpisodeIds, parse_episodes


def run(args: argparse.Namespace) -> int:
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
