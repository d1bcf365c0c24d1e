"""An experiment's trainings as Ray tasks (experiment --ray): the same train_seed the process pool of
--jobs runs, one task per training, scheduled by Ray on a local Ray or on a cluster (docs/scaling.md)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

from tracelab.train.experiments.runner import CLOSE_WAIT_S, SeedRun, train_seed
from tracelab.train.ray_session import LOCAL, ray_session


def in_ray_tasks(args: list[tuple], address: str = LOCAL) -> list[SeedRun]:
    """train_seed on each of `args` (its positional arguments, the run directory third), one Ray task of
    one CPU each, results in the order of `args`. The run directories go to the workers as absolute paths
    (a worker's working directory is not ours; on a cluster --out must be a folder every node sees at the
    same path). Any way out before all are done (Ctrl-C, SIGTERM, a failed training) cancels the tasks: a
    running one gets KeyboardInterrupt, which closes its run as 'interrupted'."""
    with ray_session(address) as ray:
        task = ray.remote(num_cpus=1, max_retries=0)(train_seed)
        given = [Path(a[2]) for a in args]
        refs = [task.remote(*a[:2], run_dir.absolute(), *a[3:]) for a, run_dir in zip(args, given)]
        try:
            runs = ray.get(refs)
        except BaseException:
            for ref in refs:
                ray.cancel(ref)  # not force: the training stops as on Ctrl-C and closes its run
            ray.wait(refs, num_returns=len(refs), timeout=CLOSE_WAIT_S)
            raise
    # the paths as the experiment gave them, as the process pool's results have them
    return [dataclasses.replace(sr, run_dir=run_dir, policy_dir=run_dir / "policy" if sr.policy_dir else None)
            for sr, run_dir in zip(runs, given)]
