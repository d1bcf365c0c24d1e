"""`tracelab whatif RUN --episode E --at T --action NAME`: a recorded game of a spec world rebuilt at step
T from the run (tracelab/envs/declared/branch.py), NAME taken there instead, played on by a policy or
the recorded actions, recorded as the one episode of a new run that names its origin, and printed beside
the original (tracelab/store/branch_compare.py). docs/whatif.md."""
from __future__ import annotations

import argparse
import json
import shlex
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tracelab.commands._args import non_negative_int, positive_int
from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.commands._recording import recording_into
from tracelab.errors import UserError, store_errors

if TYPE_CHECKING:
    from tracelab.store.branch_compare import BranchComparison


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("whatif", help="replay a recorded game of a spec world to a step, take another action "
                                      "there, play on, and show the branch beside the original",
                       description="Rebuild the world of episode E at step T from the run (its spec and rule "
                                   "texts, its seeds, its recorded actions), take NAME at step T instead, "
                                   "play on with --policy's greedy actions or the recorded ones, record the "
                                   "branch as the one episode of a new run (--run) that names its origin, "
                                   "and print both games' return, outcome, return by reward term and first "
                                   "divergence.")
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/ (a spec world's: play --env, "
                               "train --env's traced evaluations)")
    p.add_argument("--episode", "-e", type=non_negative_int, required=True, help="the episode to branch")
    p.add_argument("--at", type=positive_int, required=True, help="the step (from 1) whose action is replaced")
    p.add_argument("--action", required=True, metavar="NAME", help="the action taken at --at, by its name in the "
                                                                   "spec's [actions]")
    p.add_argument("--agent", default=None, help="the agent whose action is replaced (default: the run's only one)")
    p.add_argument("--policy", default=None, metavar="RUN/policy",
                   help="play on with this policy's greedy actions (trained by train --env on the run's env); "
                        "default: the recorded actions, until they run out")
    p.add_argument("--steps", type=positive_int, default=None, help="play at most this many steps after --at")
    p.add_argument("--run", dest="out", default=None, metavar="OUT",
                   help="a new (or empty) run directory for the branch (default runs/whatif-<run>-e<E>-t<T>-<time>)")
    p.add_argument("--json", action="store_true", help="the comparison as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # deferred: loads DuckDB, gymnasium and the engine; every command is imported to build the CLI's parser
    from tracelab.envs.declared.branch import plan_branch, rebuilt_spec
    from tracelab.store.reader import open_run, resolve_run, run_info

    with store_errors(), ctrl_c_stops_queries():
        origin_dir = resolve_run(args.run).resolve()
        run_id = str(run_info(origin_dir).meta.get("run_id") or origin_dir.name)
        con = open_run(origin_dir)
        try:
            plan = plan_branch(con, args.run, run_id, args.episode, args.at, args.agent, args.steps)
        finally:
            con.close()
    with rebuilt_spec(plan.world) as spec:
        plan.rehearse(spec, args.action)
        policy = _policy(args.policy, plan.world) if args.policy else None
        out = Path(args.out or f"runs/whatif-{origin_dir.name}-e{args.episode}-t{args.at}-"
                               f"{time.strftime('%Y%m%d-%H%M%S')}")
        origin = plan.origin(spec, str(origin_dir), args.policy)
        writer = _open_writer(out, _meta(args, plan, spec, origin))
        with recording_into(writer, out):
            played = plan.play(spec, writer, policy, begin_info={"whatif": origin.to_json()})
    with store_errors(), ctrl_c_stops_queries():
        comparison = _compare(origin_dir, out, origin)
    if args.json:
        doc = {**comparison.to_dict(), "run": str(out), "stopped": played["stopped"]}
        print(json.dumps(doc, indent=1, default=str))
    else:
        print(render(comparison, played["stopped"]))
        print(f"\nbranch written to {out}/  — tracelab diff {shlex.quote(str(out))} {shlex.quote(str(args.run))}")
    return 0


def _policy(path: str, world: Any) -> Any:
    # deferred: loads torch
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.train.env_policy import load_trained
    with store_errors():  # a policy that does not load, or was trained on another env
        return load_trained(path, EnvSource(world.env, dict(world.env_args)))


def _meta(args: argparse.Namespace, plan: Any, spec: Any, origin: Any) -> dict[str, Any]:
    """The branch run's metadata: the command, the origin's env as it names it, the spec's summaries and
    facts (recording.declared_run_config), the origin (branch_origin.ORIGIN_KEY)."""
    # deferred: loads gymnasium and the engine
    from tracelab.envs.declared.recording import declared_run_config
    from tracelab.store.branch_origin import ORIGIN_KEY
    w = plan.world
    config = {"env": w.env, "env_id": w.env_id, "spec_path": w.spec_path, "env_args": w.env_args, "episodes": 1,
              "policy": args.policy or "recorded", **declared_run_config(spec), ORIGIN_KEY: origin.to_json()}
    return {"command": " ".join(shlex.quote(a) for a in ["tracelab", *args.argv]), "config": config,
            "rule_files": list(spec.program.files), "seed": plan.seed}


def _open_writer(out: Path, meta: dict[str, Any]) -> Any:
    # deferred: loads DuckDB
    from tracelab.store import TraceWriter
    from tracelab.store.layout import check_new_run_dir
    check_new_run_dir(out)
    try:
        with store_errors():  # another process took the directory since the check: a RuntimeError
            return TraceWriter.open(out, meta)
    except OSError as e:
        raise UserError(f"cannot create the run directory {out}: {e.strerror or e}") from e


def _compare(origin_dir: Path, out: Path, origin: Any) -> "BranchComparison":
    # deferred: loads DuckDB
    from tracelab.store.branch_compare import compare_branch
    from tracelab.store.reader import open_run, retrying
    a, b = open_run(origin_dir), open_run(out)
    try:
        return retrying(lambda: compare_branch(a, origin_dir.name, b, out.name, origin))
    finally:
        a.close()
        b.close()


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def render(c: "BranchComparison", stopped: str | None) -> str:
    """The two games side by side (steps, return, outcome, return by term), then diff's first divergence."""
    # deferred: loads DuckDB
    from tracelab.store.diff import render_divergence
    o, b = c.original, c.branch
    terms = list(dict.fromkeys([*o.by_term, *b.by_term]))
    rows = [["", f"original {o.name}:{o.episode}", f"branch {b.name}:{b.episode}"],
            ["steps", str(o.steps), str(b.steps)],
            ["return", _fmt(o.ret), _fmt(b.ret)],
            ["outcome", o.outcome or "unfinished", b.outcome or "unfinished"],
            *([f"  {t}", _fmt(o.by_term.get(t, 0.0)), _fmt(b.by_term.get(t, 0.0))] for t in terms)]
    if terms:
        rows.insert(4, ["return by term", "", ""])
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    lines = [c.origin.describe()]
    lines += ["  ".join(x.ljust(w) for x, w in zip(r, widths)).rstrip() for r in rows]
    if stopped:
        lines.append(f"the branch stopped before its end: {stopped}")
    return "\n".join(lines) + "\n\n" + render_divergence(c.divergence)
