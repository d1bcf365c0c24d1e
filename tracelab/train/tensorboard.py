"""Training metrics as TensorBoard event files (the optional `tensorboard` extra), for users who keep their
curves there: `train --tensorboard DIR` writes them while training (TensorBoardSink, one of the
Trainer's metric sinks), `tracelab export RUN --tensorboard DIR` converts a run's `metrics` afterwards
(export_metrics). Either way a run's scalars go to DIR/<run name>/, so that `tensorboard --logdir DIR`
shows runs side by side under the names the store gives them; the store stays the record.

The writer is torch's SummaryWriter (torch.utils.tensorboard), which needs the tensorboard package."""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

from tracelab.errors import UserError

# deferred: the tensorboard package, optional (tracelab[tensorboard]), when events are written; the store's reader
# (DuckDB) only to export a run's metrics, which writing events live does not need

INSTALL_HINT = ("writing TensorBoard event files needs the tensorboard package: "
                "pip install 'tracelab[tensorboard]' (or pip install tensorboard)")
EVENTS_GLOB = "events.out.tfevents.*"
FLUSH_SECS = 5  # while training, events reach the file at least this often (TensorBoard re-reads them)


class MetricSink(Protocol):
    """Where a Trainer sends its metric rows besides the run (the run itself is written by TraceWriter)."""

    def write(self, step: int, values: Mapping[str, float]) -> None: ...

    def flush(self) -> None: ...


def summary_writer_class() -> Any:
    """torch's SummaryWriter, or a UserError saying how to install what it needs."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError as e:
        raise UserError(INSTALL_HINT) from e
    return SummaryWriter


def run_log_dir(root: Path, run_name: str, *, appending: bool = False) -> Path:
    """DIR/<run name>, checked before anything is written: DIR must be a directory (or not exist yet), and
    a log directory that already holds event files is refused unless `appending` (a run resumed in
    place continues its own): TensorBoard would mix two runs' curves under one name."""
    summary_writer_class()  # the install hint before any training starts
    if root.exists() and not root.is_dir():
        raise UserError(f"--tensorboard {str(root)!r} is not a directory")
    log_dir = root / run_name
    if not appending and log_dir.is_dir() and any(log_dir.glob(EVENTS_GLOB)):
        raise UserError(f"{str(log_dir)!r} already holds TensorBoard event files: give another --tensorboard "
                        f"DIR, or remove them")
    return log_dir


class TensorBoardSink:
    """Scalars into one log directory. `purge_step`: a run resumed in place from a checkpoint at that step
    hides the events the interrupted session wrote from there on (TensorBoard's own purge)."""

    def __init__(self, log_dir: Path, purge_step: int | None = None) -> None:
        self.log_dir = log_dir
        self.scalars = 0
        self._writer = summary_writer_class()(log_dir=str(log_dir), purge_step=purge_step,
                                              flush_secs=FLUSH_SECS)

    def write(self, step: int, values: Mapping[str, float], walltime: float | None = None) -> None:
        for name, value in values.items():
            self._writer.add_scalar(name, value, global_step=step, walltime=walltime)
        self.scalars += len(values)

    def flush(self) -> None:
        self._writer.flush()

    def close(self) -> None:
        self._writer.close()


def export_metrics(con: Any, sink: TensorBoardSink) -> dict[str, int]:
    """Every row of the run's `metrics` (con: a connection from tracelab.store.open_run) into `sink`, at
    its step and wall time, streamed in batches: memory stays bounded whatever the run's size. Returns
    {"scalars", "names", "first_step", "last_step"}."""
    from tracelab.store.reader import arrow_stream, query_readonly
    names, first, last = query_readonly(con, "SELECT count(DISTINCT name), coalesce(min(step), 0), "
                                             "coalesce(max(step), 0) FROM metrics WHERE value IS NOT NULL"
                                        ).fetchall()[0]
    rel = query_readonly(con, "SELECT step, name, value, epoch(time) AS walltime FROM metrics "
                              "WHERE value IS NOT NULL ORDER BY step, time, name")
    _, batches = arrow_stream(rel)
    for batch in batches:
        for step, name, value, walltime in zip(*(batch.column(i).to_pylist() for i in range(4))):
            sink.write(step, {name: value}, walltime)
    sink.flush()
    return {"scalars": sink.scalars, "names": names, "first_step": first, "last_step": last}
