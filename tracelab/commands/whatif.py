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

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.commands._recording import recording_into
from tracelab.envs.declared.branch import plan_branch, rebuilt_spec
from tracelab.envs.declared.env_source import EnvSource
from tracelab.errors import UserError, store_errors
from tracelab.store import TraceWriter
from tracelab.store.branch_compare import compare_branch
from tracelab.store.branch_origin import ORIGIN_KEY
from tracelab.store.diff import render_divergence
from tracelab.store.layout import check_new_run_dir
from tracelab.store.reader import open_run, resolve_run, retrying, run_info
from tracelab.envs.declared.gridwar_scenarios import load_trained

if TYPE_CHECKING:
    from tracelab.store.branch_compare import BranchComparison


def run(args: argparse.Namespace) -> int:
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
    with store_errors():  # a policy that does not load, or was trained on another env
        return load_trained(path, EnvSource(world.env, dict(world.env_args)))


def _meta(args: argparse.Namespace, plan: Any, spec: Any, origin: Any) -> dict[str, Any]:
    """The branch run's metadata: the command, the origin's env as it names it, the origin
    (branch_origin.ORIGIN_KEY); the recorder adds the spec's summaries, facts and board
    (recording.declared_run_config)."""
    w = plan.world
    config = {"env": w.env, "env_id": w.env_id, "spec_path": w.spec_path, "env_args": w.env_args, "episodes": 1,
              "policy": args.policy or "recorded", ORIGIN_KEY: origin.to_json()}
    return {"command": " ".join(shlex.quote(a) for a in ["tracelab", *args.argv]), "config": config,
            "rule_files": list(spec.program.files), "seed": plan.seed}


def _open_writer(out: Path, meta: dict[str, Any]) -> Any:
    check_new_run_dir(out)
    try:
        with store_errors():  # another process took the directory since the check: a RuntimeError
            return TraceWriter.open(out, meta)
    except OSError as e:
        raise UserError(f"cannot create the run directory {out}: {e.strerror or e}") from e


def _compare(origin_dir: Path, out: Path, origin: Any) -> "BranchComparison":
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
