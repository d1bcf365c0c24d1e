"""A first run's compile on two cores: while a RuleSim's process compiles the engine's step kernel (the
longest compile, ~13 s of CPU), a second process compiles the game's kernels (read-back, observations,
actions, the opponent, the fused step's buffers: ~10 s) into numba's disk cache, and the RuleSim loads
them from there instead of compiling them after its first step (docs/benchmarks/history.md, issue 31 part 4).

numba compiles under one lock per process, so threads cannot share the work; processes can, through the
disk cache (a function compiled by the second process is loaded by the first when it first calls it).
The second process builds the same RuleSim (the same code makes the same argument types, so the same
signatures) except that its engine never steps: it never compiles the step kernel, which is the first
process's share. It is started only when both shares are to compile (a cold cache), and the RuleSim
waits for it after its own first step; if it fails or is slow, the RuleSim simply compiles what is
missing itself, as before.

This module is the first process's side (start, wait, stop); the second process runs
tracelab/game/rulesim_warmup_child.py:

    python -m tracelab.game.rulesim_warmup_child   (the RuleSim's arguments as JSON on stdin, from `start`)
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from typing import IO, Any

from tracelab.engine.numba_cache import all_cached, is_cached
from tracelab.game.observe import observe_step
from tracelab.game.opponent import _policy_kernel
from tracelab.game.rulesim_fused import _make_buffers
from tracelab.game.rulesim_kernel import encode_actions, read_and_settle, read_back
from tracelab.game.scenario import Scenario

# deferred: the engine kernel asked for only (tracelab.engine.lanes or .kernel): each module compiles its own

WAIT_S = 600  # a compile that takes longer is left to die; the RuleSim compiles what it still lacks


def game_kernels(fused: bool) -> tuple[Any, ...]:
    """The numba functions a RuleSim calls besides the engine's step kernel (those the second process
    compiles)."""
    kernels = (read_back, read_and_settle, observe_step, encode_actions, _policy_kernel)
    return kernels + (_make_buffers,) if fused else kernels


def _step_kernel(engine_kernel: str) -> Any:
    if engine_kernel == "lanes":
        from tracelab.engine.lanes import step_lanes
        return step_lanes
    from tracelab.engine.kernel import step_worlds
    return step_worlds


class Warmup:
    """The second process: wait() for it (its status: "ready", "failed" or "timeout"), or stop() it."""

    def __init__(self, proc: subprocess.Popen, log: IO[bytes]) -> None:
        self.proc, self.log = proc, log
        self.status = "running"
        self.why = ""  # a failure's last line of output (a traceback's error)

    def wait(self, timeout: float = WAIT_S) -> str:
        if self.status != "running":
            return self.status
        try:
            code = self.proc.wait(timeout)
            self.status = "ready" if code == 0 else "failed"
            if code != 0:
                self.log.seek(0)
                lines = self.log.read()[-4096:].decode(errors="replace").splitlines()
                self.why = f"exit status {code}: {lines[-1] if lines else 'no output'}"
        except subprocess.TimeoutExpired:
            self.stop()
            self.status = "timeout"
        self.log.close()
        return self.status

    def stop(self) -> None:
        """End it now (the RuleSim failed or was interrupted): what it compiled so far stays cached."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.status = "stopped" if self.status == "running" else self.status
        self.log.close()


def needed(engine_kernel: str, fused: bool) -> bool:
    """Worth a second process: the engine's step kernel and some game kernel both still to compile."""
    if engine_kernel not in ("counting", "lanes"):  # a compiled kernel is built by `tracelab compile`
        return False
    return is_cached(_step_kernel(engine_kernel)) is False and all_cached(game_kernels(fused)) is False


def start(scenario: Scenario, n_worlds: int, stack_previous: bool, engine_kernel: str, fused: bool) -> Warmup | None:
    """The second process compiling the game's kernels of this RuleSim, when needed() (else None)."""
    if not needed(engine_kernel, fused):
        return None
    log = tempfile.TemporaryFile()  # its output: Warmup.why on a failure
    try:
        # -P: not the current folder first on sys.path, where another checkout's tracelab/ would be found
        proc = subprocess.Popen([sys.executable, "-P", "-m", "tracelab.game.rulesim_warmup_child"],
                                stdin=subprocess.PIPE, stdout=log, stderr=log)
    except OSError:  # no process to spare: this one compiles everything, as without it
        log.close()
        return None
    assert proc.stdin is not None
    try:  # a few KB: the pipe's buffer takes it without waiting for the child to read
        proc.stdin.write(to_child(scenario, n_worlds, stack_previous, engine_kernel, fused))
        proc.stdin.close()
    except OSError:  # the child died first; wait() sees its status
        pass
    return Warmup(proc, log)


def to_child(scenario: Scenario, n_worlds: int, stack_previous: bool, engine_kernel: str, fused: bool) -> bytes:
    """What the second process reads on stdin: the RuleSim's arguments as JSON, the scenario as its TOML
    text (read back as a scenario file is, its arrays read-only: a pickled one would come back writable,
    another argument type, and the kernels would compile for it in vain)."""
    return json.dumps({"scenario": scenario.to_toml(), "n_worlds": n_worlds, "stack_previous": stack_previous,
                       "kernel": engine_kernel, "fused": fused}).encode()
