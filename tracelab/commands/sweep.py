"""`tracelab sweep`: a hyperparameter search over TrainConfig's fields with Ray Tune, each trial an
ordinary run under --out, the best trial named at the end (docs/scaling.md "Sweeps")."""
from __future__ import annotations

import argparse
import shlex
import signal
import sys
import time
from pathlib import Path

from tracelab.commands._interrupt import CtrlCStops
from tracelab.envs.declared.gridwar_scenarios import ScenarioTraining
from tracelab.envs.declared.env_source import EnvSource, parse_env_args
from tracelab.errors import UserError, store_errors
from tracelab.train.env_source import probe_env
from tracelab.train.memory import memory_limit
from tracelab.train.ray_session import check_address, ray_session
from tracelab.train.sweep import run_sweep
from tracelab.train.sweep_spec import build_spec, check_trials_memory


def run(args: argparse.Namespace) -> int:
    spec = build_spec(sets=args.set, grids=args.grid, randoms=args.random, file=args.spec, samples=args.samples,
                      scheduler=args.scheduler, metric=args.metric, mode=args.mode)
    with store_errors():  # a scenario file, an env or a spec that does not load
        if spec.env is not None:
            world = source = EnvSource.given(spec.env, parse_env_args(args.env_arg))
        elif args.env_arg:
            raise UserError("--env-arg needs --set env=SPEC_OR_ID")
        else:
            world = ScenarioTraining.given(spec.scenario)
            source = world.source
        probe = probe_env(source)  # a bad id, spec or keyword argument: one line, before Ray starts
    check_trials_memory(spec, probe, memory_limit(args.max_memory, "--max-memory"))
    out = Path(args.out or _default_out())
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UserError(f"{out} is not empty: give another --out or remove it")
    check_address(args.ray)  # the install hint, or an address where nothing answers, before anything starts

    command = " ".join(shlex.quote(a) for a in ["tracelab", "sweep", *args.argv[1:]])
    say = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731
    say(f"sweep: {spec.trials} trial{'s' * (spec.trials != 1)} ({'; '.join(a.describe() for a in spec.axes)}; "
        f"scheduler {spec.scheduler}, {spec.mode} {spec.metric}), runs in {out}/")

    def terminated(signum: int, frame: object) -> None:  # SIGTERM stops the sweep as Ctrl-C does
        signal.raise_signal(signal.SIGINT)

    previous = signal.signal(signal.SIGTERM, terminated)
    # Ctrl-C during the search is Tune's (it stops the trials, whose runs close as interrupted, and returns):
    # CtrlCStops sees the press through the wakeup fd and ends the command with status 130 after the list
    stopped = CtrlCStops(lambda: None, f"the sweep was stopped (its trials' runs are closed, in {out})")
    try:
        with stopped:
            with ray_session(args.ray):
                result = run_sweep(spec, world, out, command)
            for t in sorted(result.trials, key=lambda t: t["run"]):
                shown = ("no evaluation" if t["value"] is None
                         else f"best {spec.metric} {t['value']:.3f} at step {t['step']:,} (last {t['last']:.3f})")
                failed = f" (failed: {t['error']})" if t["error"] else ""
                say(f"  {t['run']}: {_values(t['config'])}: {shown}{failed}")
            if stopped.pressed.is_set():
                return 130  # CtrlCStops raises KeyboardInterrupt on the way out
    finally:
        signal.signal(signal.SIGTERM, previous)
    if result.best_dir is None:
        raise UserError(f"no trial reported {spec.metric} (see the runs in {out})")
    best = next(t for t in result.trials if t["run"] == result.best_dir)
    print(f"best trial: {result.best_dir}  {_values(result.best_config)}  ({spec.metric} {result.best_value:.3f} "
          f"at step {best['step']:,})")
    return 0


def _values(config: dict) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in config.items())


def _default_out() -> str:
    return f"runs/sweeps/sweep-{time.strftime('%Y%m%d-%H%M%S')}"
