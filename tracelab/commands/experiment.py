"""`tracelab experiment NAME`: one of the method's experiments (docs/experiments/): train every setting
once per seed, evaluate against both opponent settings, write the figures into the runs and a markdown
report with PNG plots."""
from __future__ import annotations

import argparse
import shlex
import signal
import sys
from pathlib import Path

from tracelab.errors import UserError, store_errors
from tracelab.train.experiments.definitions import EXPERIMENTS
from tracelab.train.experiments.report import write_report
from tracelab.train.experiments.run import load_result, run_experiment, scaled
from tracelab.train.ray_session import check_address

def run(args: argparse.Namespace) -> int:
    exp = EXPERIMENTS[args.name]
    budget = scaled(exp.quick if args.quick else exp.full, args.seeds, args.steps, args.eval_games)
    out = Path(args.out or f"runs/experiments/{args.name}")
    report_dir = Path(args.report_dir or (out if args.quick else "docs/experiments"))
    try:
        import matplotlib  # noqa: F401  (fail before training, not after)
    except ImportError:
        raise UserError("the experiment plots need matplotlib: pip install 'tracelab[experiments]'") from None
    if args.report_only:
        return _report_again(exp, out, report_dir)
    if args.ray is not None:
        if any(a.env is not None for a in exp.arms):
            raise UserError(f"--ray runs the war game's experiments only for now; {exp.name} trains a world of "
                            f"its own: use --jobs")
        if args.jobs > 1:
            raise UserError("--jobs and --ray: Ray decides how many trainings run at a time; give one of them")
        check_address(args.ray)  # the install hint, or an address where nothing answers, before any training
    taken = [out / f"{a.slug}-seed{s}{tail}" for a in exp.arms for s in range(budget.seeds)
             for tail in ("", "-traces") if (out / f"{a.slug}-seed{s}{tail}").exists()]
    if taken:
        raise UserError(f"{taken[0]} already exists: give another --out or remove it")

    command = " ".join(shlex.quote(a) for a in ["tracelab", *sys.argv[1:]])
    if not command.startswith("tracelab experiment"):
        command = f"tracelab experiment {args.name}" + (" --quick" if args.quick else "")
    say = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731
    def terminated(signum: int, frame: object) -> None:  # SIGTERM (a scheduler, kill): stop like Ctrl-C
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, terminated)
    try:
        result = run_experiment(exp, budget, out, command, args.quick, say, jobs=args.jobs, kernel=args.kernel,
                                ray=args.ray)
    except KeyboardInterrupt:  # main() prints this and exits 130
        raise KeyboardInterrupt(f"no report written (the runs so far are in {out})") from None
    finally:
        signal.signal(signal.SIGTERM, previous)
    path = write_report(result, report_dir)
    print(f"report: {path}  (plots in {report_dir / exp.name}/, runs in {out}/, wall time "
          f"{result.wall_s / 60:.1f} min)")
    return 0


def _report_again(exp, out: Path, report_dir: Path) -> int:
    with store_errors():  # no finished experiment in --out
        result = load_result(exp, out)
    print(f"report: {write_report(result, report_dir)}")
    return 0
