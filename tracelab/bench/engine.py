"""`tracelab bench engine`: what the engine costs before and while it runs.

(a) first-ever compile: a fresh process with NUMBA_CACHE_DIR on an empty directory builds an Engine on
    the game program and runs its first step; (b) warm start: fresh processes with the normal cache,
    from process start to the first step, for the game program, for another rule file (no recompile:
    one compiled signature serves both) and for war.toml; (c) the spec path's steps per CPU second by
    team size (tracelab.bench.sims), tracing on and off, with the engine's work counters; (d) resident memory
    over a long traced run; (e) the big graph: load, build and run of the spread rule on random graphs
    of 2k / 20k / 200k nodes (tracelab/bench/biggraph.py). Figures: docs/benchmarks.md."""
from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import tempfile
import time
from typing import IO, Any

from tracelab import RULES_DIR
from tracelab.bench import biggraph
from tracelab.bench.common import (
    fmt_num,
    format_table,
    machine_info,
    rss_bytes,
    summarize,
)

# deferred: the simulators (tracelab.bench.sims) load numba, which machine_line's importers (bench tui, bench
# replay) do not need

REFERENCE_S_PER_STEP = 0.8  # the method's reference system: ~0.8 s per step
GOAL_STEPS_PER_S = 20_000  # single 1v1 world, tracing on
OTHER_PROGRAM = str(RULES_DIR / "examples" / "reach.rules")
MEMORY_TOLERANCE_MB = 2.0  # RSS growth after warm-up above this counts as growth


class Probe:
    """One run of `python -m tracelab.bench.probe TARGET...`, started at once; result() waits for it and
    returns its JSON lines, each with `since_start_s`: seconds from spawning the process to the line."""

    def __init__(self, targets: list[str], cache_dir: str | None = None, timeout_s: float = 1800) -> None:
        env = dict(os.environ)
        if cache_dir is not None:
            env["NUMBA_CACHE_DIR"] = cache_dir
        self.timeout_s = timeout_s
        self._err: IO[str] = tempfile.TemporaryFile("w+")
        self._t0 = time.perf_counter()
        self.proc = subprocess.Popen([sys.executable, "-m", "tracelab.bench.probe", *targets], env=env,
                                     stdout=subprocess.PIPE, stderr=self._err, text=True)

    def result(self) -> list[dict[str, Any]]:
        lines = []
        assert self.proc.stdout is not None
        for line in self.proc.stdout:  # timestamped as each line arrives
            rec = json.loads(line)
            rec["since_start_s"] = time.perf_counter() - self._t0
            lines.append(rec)
        code = self.proc.wait(timeout=self.timeout_s)
        self._err.seek(0)
        err = self._err.read()
        self._err.close()
        if code != 0:
            raise RuntimeError(f"bench probe failed (exit {code}):\n{err[-2000:]}")
        return lines


class ColdCompile:
    """(a) The first-ever compile, `repeats` times, each in a fresh process on an empty cache directory.
    start() launches the first process, so it can overlap other work (--quick does this)."""

    def __init__(self, repeats: int) -> None:
        self.repeats = max(1, repeats)
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self._probe: Probe | None = None

    def start(self) -> "ColdCompile":
        self._tmp = tempfile.TemporaryDirectory(prefix="tracelab-bench-numba-")
        self._probe = Probe(["game"], cache_dir=self._tmp.name)
        return self

    def result(self) -> dict[str, Any]:
        runs = []
        for i in range(self.repeats):
            if self._probe is None:
                self.start()
            assert self._probe is not None and self._tmp is not None
            try:
                runs.append(self._probe.result()[0])
            finally:
                self._tmp.cleanup()
                self._probe = None
        return {"program": "war.toml's advanced game (its program and facts)", "runs": len(runs),
                "build_and_first_step_s": summarize([r["build_s"] + r["step_s"] for r in runs]).to_dict(),
                "process_to_first_step_s": summarize([r["since_start_s"] for r in runs]).to_dict()}


def warm_start(repeats: int) -> dict[str, Any]:
    """(b) Fresh processes with the normal cache: process start to first step for the game program, for
    another rule file alone, and for war.toml (one world); the second program's build and step in a
    process that ran the game first; the compiled signatures of step_worlds after both."""
    Probe(["game", "spec"]).result()  # fill the cache if a source changed since it was written
    game, second, other, spec, build, signatures = [], [], [], [], [], []
    for _ in range(max(1, repeats)):
        both = Probe(["game", OTHER_PROGRAM]).result()
        game.append(both[0]["since_start_s"])
        build.append(both[0]["build_s"] + both[0]["step_s"])
        second.append(both[1]["build_s"] + both[1]["step_s"])
        signatures.append(both[2]["signatures"])
        other.append(Probe([OTHER_PROGRAM]).result()[0]["since_start_s"])
        spec.append(Probe(["spec"]).result()[0]["since_start_s"])
    return {"game_to_first_step_s": summarize(game).to_dict(),
            "game_build_and_first_step_s": summarize(build).to_dict(),
            "other_program": os.path.relpath(OTHER_PROGRAM, RULES_DIR.parent),
            "other_program_to_first_step_s": summarize(other).to_dict(),
            "other_program_after_game_s": summarize(second).to_dict(),
            "spec_to_first_step_s": summarize(spec).to_dict(),
            "step_worlds_signatures": max(signatures), "one_signature": max(signatures) == 1}


def step_rates(agents: list[int], repeats: int, target_s: float, kernel: str = "auto") -> list[dict[str, Any]]:
    """(c) The spec path's steps per CPU second for each team size (war.toml's base game), one world,
    tracing on and off (engine kernel `kernel`), with the engine's work counters per step."""
    from tracelab.bench.sims import SpecLoop, cpu_rates, team_spec
    from tracelab.envs.declared.vector_world import DeclaredWorlds
    rows = []
    for n in agents:
        t0 = time.perf_counter()
        worlds = DeclaredWorlds(team_spec(n), 1, kernel)
        build_s = time.perf_counter() - t0
        eng = worlds.engine
        for trace in (True, False):
            loop, steps = SpecLoop(worlds, trace), [0]

            def counted(k: int, loop: SpecLoop = loop, steps: list[int] = steps) -> None:
                loop.run(k)
                steps[0] += k
            before = eng.stats
            rates = cpu_rates(counted, 1, repeats, target_s)
            after = eng.stats
            rows.append({"agents": n, "trace": trace, "kernel": eng.kernel, "steps_per_s": rates,
                         "stats_per_step": {k: float((after[k] - before[k]).sum()) / max(steps[0], 1)
                                            for k in after},
                         "build_s": build_s, "atoms": int(eng.lower.shape[1]),
                         "groundings": len(eng.groundings.rule)})
    return rows


def memory(steps: int) -> dict[str, Any]:
    """(d) RSS of this process every 10% of a `steps`-step traced 1v1 run of the spec path (the trace taken
    as the envs take it)."""
    from tracelab.bench.sims import SpecLoop, team_spec
    from tracelab.envs.declared.vector_world import DeclaredWorlds
    loop = SpecLoop(DeclaredWorlds(team_spec(1), 1), trace=True)
    gc.collect()
    marks = [round(i * steps / 10) for i in range(11)]
    samples = [{"step": 0, "rss_mb": rss_bytes() / 2**20}]
    for a, b in zip(marks, marks[1:]):
        loop.run(b - a)
        samples.append({"step": b, "rss_mb": rss_bytes() / 2**20})
    warm = samples[1]["rss_mb"]  # after the first 10%: buffers have reached their working size
    growth = samples[-1]["rss_mb"] - warm
    peak_growth = max(s["rss_mb"] for s in samples[1:]) - warm
    return {"steps": steps, "samples": samples, "warmup_steps": marks[1], "growth_after_warmup_mb": growth,
            "peak_growth_after_warmup_mb": peak_growth, "tolerance_mb": MEMORY_TOLERANCE_MB,
            "grew": peak_growth > MEMORY_TOLERANCE_MB}


def reference_figure(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The 1v1 traced steps/s against the reference system's 0.8 s/step and the 20,000 steps/s goal."""
    row = next(r for r in rows if r["agents"] == 1 and r["trace"])
    rate = row["steps_per_s"]["median"]
    return {"reference_s_per_step": REFERENCE_S_PER_STEP, "steps_per_s": rate,
            "speedup": rate * REFERENCE_S_PER_STEP, "goal_steps_per_s": GOAL_STEPS_PER_S,
            "goal_met": rate >= GOAL_STEPS_PER_S}


def run(quick: bool = False, repeats: int = 5, compile_repeats: int | None = None,
        agents: list[int] | None = None, graph_only: bool = False, kernel: str = "auto") -> dict[str, Any]:
    """Every engine figure. --quick: small sizes, one process per start-up figure, and no first-ever
    compile unless `compile_repeats` asks for it (it then overlaps the in-process work, so its figure is
    only a smoke value). `graph_only`: the big-graph section alone."""
    info = machine_info()
    big = biggraph.run(quick, 1 if quick else min(repeats, 3))
    if graph_only:
        info["load_average_end"] = machine_info()["load_average"]
        return {"machine": info, "quick": quick, "repeats": repeats, "big_graph": big}
    n_compiles = (compile_repeats or 0) if quick else (compile_repeats or min(repeats, 3))
    cold = ColdCompile(n_compiles) if n_compiles else None
    compiled: dict[str, Any] = {"skipped": "--quick (a compile takes 30-70 s here); add --compile-repeats 1"}
    if cold and quick:
        cold.start()
    elif cold:
        compiled = cold.result()
    mem = memory(5_000 if quick else 100_000)
    rows = step_rates(agents or ([1, 2] if quick else [1, 5, 20]), repeats, 0.1 if quick else 1.0, kernel)
    if cold and quick:
        compiled = cold.result()
    if cold:
        compiled["overlapped"] = quick
    warm = warm_start(1 if quick else repeats)
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "kernel": kernel, "first_compile": compiled,
            "warm_start": warm, "steps": rows, "memory": mem, "reference": reference_figure(rows),
            "big_graph": big}


def report(r: dict[str, Any]) -> str:
    """The human-readable tables of run()'s result."""
    if "first_compile" not in r:  # the big-graph section alone
        return "\n\n".join([machine_line(r["machine"], r["quick"], r["repeats"]), biggraph.report(r["big_graph"])])
    c, w, m, ref = r["first_compile"], r["warm_start"], r["memory"], r["reference"]
    med = lambda d: d["median"]  # noqa: E731
    sp = lambda d: f"{100 * d['spread']:.0f}%"  # noqa: E731
    compile_rows = [] if "skipped" in c else [
        ["first-ever compile: build + first step" + (" (overlapped)" if c["overlapped"] else ""),
         med(c["build_and_first_step_s"]), sp(c["build_and_first_step_s"]), c["runs"]],
        ["first-ever compile: process start to first step", med(c["process_to_first_step_s"]),
         sp(c["process_to_first_step_s"]), c["runs"]]]
    start = format_table(["start-up (s)", "median", "spread", "runs"], [
        *compile_rows,
        ["warm: process start to first step, game", med(w["game_to_first_step_s"]),
         sp(w["game_to_first_step_s"]), len(w["game_to_first_step_s"]["runs"])],
        ["warm: game build + first step", med(w["game_build_and_first_step_s"]),
         sp(w["game_build_and_first_step_s"]), len(w["game_build_and_first_step_s"]["runs"])],
        [f"warm: process start to first step, {w['other_program']}", med(w["other_program_to_first_step_s"]),
         sp(w["other_program_to_first_step_s"]), len(w["other_program_to_first_step_s"]["runs"])],
        [f"warm: {w['other_program']} after the game, same process", med(w["other_program_after_game_s"]),
         sp(w["other_program_after_game_s"]), len(w["other_program_after_game_s"]["runs"])],
        ["warm: process start to first step of war.toml (1v1)", med(w["spec_to_first_step_s"]),
         sp(w["spec_to_first_step_s"]), len(w["spec_to_first_step_s"]["runs"])],
    ])
    if "skipped" in c:
        start += f"\nfirst-ever compile: skipped ({c['skipped']})"
    sig = f"step_worlds signatures after both programs: {w['step_worlds_signatures']} " \
          f"({'ok' if w['one_signature'] else 'RECOMPILED'})"
    steps = format_table(
        ["agents", "trace", "kernel", "steps/CPU s", "spread", "firings", "changes", "watch visits", "candidates",
         "build s"],
        [[s["agents"], "on" if s["trace"] else "off", s["kernel"], med(s["steps_per_s"]), sp(s["steps_per_s"]),
          s["stats_per_step"]["firings"], s["stats_per_step"]["changes"],
          s["stats_per_step"]["watch_visits"], s["stats_per_step"]["candidates"], s["build_s"]]
         for s in r["steps"]])
    mem = "  ".join(f"{s['step']:,}:{s['rss_mb']:.1f}" for s in m["samples"])
    mem_line = (f"RSS MB by step over {m['steps']:,} traced 1v1 steps: {mem}\n"
                f"growth after warm-up ({m['warmup_steps']:,} steps): {m['growth_after_warmup_mb']:+.2f} MB "
                f"(peak {m['peak_growth_after_warmup_mb']:+.2f}; tolerance {m['tolerance_mb']} MB) -> "
                f"{'GREW' if m['grew'] else 'no growth'}")
    ref_line = (f"1v1 traced: {fmt_num(ref['steps_per_s'])} steps/s = {fmt_num(ref['speedup'])}x the "
                f"reference system's {ref['reference_s_per_step']} s/step; goal >= "
                f"{ref['goal_steps_per_s']:,} steps/s: {'met' if ref['goal_met'] else 'not met'}")
    return "\n\n".join([machine_line(r["machine"], r["quick"], r["repeats"]), start + "\n" + sig,
                        "war.toml's base game, one world (work counters per step)\n" + steps,
                        mem_line, ref_line,
                        biggraph.report(r["big_graph"])])


def machine_line(info: dict[str, Any], quick: bool, repeats: int) -> str:
    load = "/".join(str(x) for x in info["load_average"])
    end = info.get("load_average_end")
    return (f"{info['cores']} cores, load {load}" + (f" -> {'/'.join(map(str, end))}" if end else "")
            + f", numba {info['versions']['numba']}, numpy {info['versions']['numpy']}, python "
            f"{info['python']}; medians of {repeats} repeats{' (quick)' if quick else ''}")
