"""`tracelab bench env`: the rule-driven simulator (RuleSim) and the hand-written one (RefSim) side by
side, by team size, one world and batched, RuleSim with tracing on and off; then GridWar's registered id
through gymnasium (gym.make, gym.make_vec: the declared env over rules/gridworld/war.toml); then GridWar
through both paths: RuleSim's vector env (tracelab.envs.vector_env, the trainer's) against the declared
spec's (docs/worlds.md), one world and batched, with their ratios; then the spec path with every agent of a
team playing (war.toml's base game at each team size: its advanced game plays one agent a team) beside RuleSim
and RefSim on the same scenario, ratios to RefSim (issue 38's speed points). Goals: docs/benchmarks.md."""
from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np

from tracelab.envs.declared.gridwar import WAR_SPEC
from tracelab.bench.common import (
    block_rates,
    calibrate,
    fmt_num,
    format_table,
    machine_info,
    summarize,
)
from tracelab.bench.engine import GOAL_STEPS_PER_S, machine_line
from tracelab.bench.sims import Loop, get_sim, measure, measure_engine_only, release, scenario_for
from tracelab.envs import make_env, make_vec_env
from tracelab.envs.declared.gridwar import scenario_spec
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.spec_size import SpecTooBig
from tracelab.envs.declared.vector_world import DeclaredWorlds
from tracelab.envs.tracer import handover_due
from tracelab.game.refsim import RefSim
from tracelab.game.rulesim import RuleSim
from tracelab.game.scenario import Scenario, builtin_scenario

# deferred: gymnasium and RuleSim's vector env (the game's numba glue) load in the sections that measure them

GOAL_BATCHED_ENV_STEPS_PER_S = 1_000_000  # batched, tracing off
GOAL_MAX_SLOWDOWN = 5.0  # rule-driven within 5x of the hand-written simulator
ENV_ID = "tracelab/GridWar-advanced-v0"


def sim_rates(agents: list[int], worlds: list[int], repeats: int, target_s: float,
              kernel: str = "auto") -> list[dict[str, Any]]:
    """One row per (agents, worlds): RefSim, RuleSim (engine kernel `kernel`) traced and untraced, and the
    ratios."""
    rows = []
    for n in agents:
        for w in worlds:
            ref, _ = get_sim("reference", n, w)
            rules, build_s = get_sim("rules", n, w, kernel)
            row = {"agents": n, "worlds": w, "rules_build_s": build_s, "rules_kernel": rules.engine.kernel,
                   "reference": measure(ref, False, repeats, target_s),
                   "rules_trace_off": measure(rules, False, repeats, target_s, engine_time=False),
                   "rules_trace_on": measure(rules, True, repeats, target_s, engine_time=False)}
            if n == 1:  # the engine alone on the same steps: the ceiling of the 1v1 goals on this machine
                row["engine_only"] = engine_only_rates(n, w, repeats, target_s, kernel)
            ref_rate = row["reference"]["steps_per_s"]["median"]
            row["rules_over_reference"] = row["rules_trace_off"]["steps_per_s"]["median"] / ref_rate
            row["rules_traced_over_reference"] = row["rules_trace_on"]["steps_per_s"]["median"] / ref_rate
            rows.append(row)
            if w > 1:  # batched sims of big teams hold gigabytes
                release("reference", n, w)
                release("rules", n, w, kernel)
    return rows


def engine_only_rates(agents: int, worlds: int, repeats: int, target_s: float,
                      kernel: str = "auto") -> dict[str, Any]:
    """The engine of a RuleSim alone, tracing off and on, replaying the stepping loop's own steps
    (sims.measure_engine_only), on a simulator built for it and dropped afterwards."""
    sim = RuleSim(scenario_for(agents), worlds, seed=0, trace=True, kernel=kernel)
    return {"trace_off": measure_engine_only(sim, False, repeats, target_s),
            "trace_on": measure_engine_only(sim, True, repeats, target_s)}


def goals(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The three goals with the measured value and met / not met."""
    single = next(r for r in rows if r["agents"] == 1 and r["worlds"] == 1)
    batched = max((r for r in rows if r["agents"] == 1), key=lambda r: r["worlds"])
    slow = max(rows, key=lambda r: 1 / r["rules_over_reference"])
    traced = single["rules_trace_on"]["steps_per_s"]["median"]
    env_steps = batched["rules_trace_off"]["env_steps_per_s"]["median"]
    slowdown = 1 / slow["rules_over_reference"]
    # what the engine alone reaches on the same steps: the most the goal's figure could become here
    alone_traced = single["engine_only"]["trace_on"]["steps_per_s"]["median"]
    alone_batched = batched["engine_only"]["trace_off"]["env_steps_per_s"]["median"]
    return [
        {"goal": "rule-driven single 1v1, tracing on", "target": f">= {GOAL_STEPS_PER_S:,} steps/s",
         "measured": traced, "unit": "steps/s", "met": traced >= GOAL_STEPS_PER_S,
         "engine_alone": alone_traced},
        {"goal": f"rule-driven batched 1v1 ({batched['worlds']} worlds), tracing off",
         "target": f">= {GOAL_BATCHED_ENV_STEPS_PER_S:,} env-steps/s", "measured": env_steps,
         "unit": "env-steps/s", "met": env_steps >= GOAL_BATCHED_ENV_STEPS_PER_S,
         "engine_alone": alone_batched},
        {"goal": f"rule-driven within {GOAL_MAX_SLOWDOWN:g}x of hand-written (worst: {slow['agents']} "
                 f"agents, {slow['worlds']} worlds, tracing off)",
         "target": f"<= {GOAL_MAX_SLOWDOWN:g}x slower", "measured": slowdown, "unit": "x slower",
         "met": slowdown <= GOAL_MAX_SLOWDOWN},
    ]


def gym_rates(worlds: int, repeats: int, target_s: float) -> dict[str, Any]:
    """Steps/s through gymnasium: the single env (gymnasium.make, 1v1) and the vector env (`worlds`
    worlds, gymnasium.make_vec) of GridWar's id, the declared spec's, tracing off."""
    import gymnasium as gym
    out: dict[str, Any] = {"env_id": ENV_ID, "vector_worlds": worlds, "trace": False, "rows": []}
    env = gym.make(ENV_ID)
    out["rows"].append({"backend": "spec", "kind": "single", "worlds": 1,
                        **block_rates(_single_runner(env), repeats, target_s)})
    env.close()
    venv = gym.make_vec(ENV_ID, num_envs=worlds)
    row = block_rates(_vector_runner(venv), repeats, target_s)
    row["env_steps_per_s"] = summarize([x * worlds for x in row["steps_per_s"]["runs"]]).to_dict()
    out["rows"].append({"backend": "spec", "kind": "vector", "worlds": worlds, **row})
    venv.close()
    return out


def declared_rates(worlds: int, repeats: int, target_s: float) -> list[dict[str, Any]]:
    """GridWar 1v1 through RuleSim (GridWarVectorEnv of 1 and `worlds` worlds: rulesim_fused, the game's own
    Python glue) and through its declared spec (DeclaredEnv, DeclaredVectorEnv over rules/gridworld/war.toml),
    base and advanced, one world and `worlds` worlds, untraced and traced (the engine's change log on,
    taken after every step), the same random actions; the ratio declared / RuleSim."""
    from tracelab.envs.vector_env import GridWarVectorEnv
    rows = []
    for name in ("base", "advanced"):
        advanced = name == "advanced"
        for kind, n, make_rules, make_declared, runner in (
                ("single", 1, lambda name=name: GridWarVectorEnv(1, name),
                 lambda advanced=advanced: make_env(WAR_SPEC, advanced=advanced), _single_runner),
                ("vector", worlds, lambda name=name: GridWarVectorEnv(worlds, name),
                 lambda advanced=advanced: make_vec_env(WAR_SPEC, worlds, advanced=advanced), _vector_runner)):
            for trace in (False, True):
                row: dict[str, Any] = {"spec": WAR_SPEC.name, "scenario": name, "kind": kind, "worlds": n,
                                       "trace": trace}
                for path, make, run in (("declared", make_declared, runner), ("rulesim", make_rules, _vector_runner)):
                    env = make()
                    rates = block_rates(run(env, _engine_of(env) if trace else None), repeats, target_s)
                    row[path] = summarize([x * n for x in rates["steps_per_s"]["runs"]]).to_dict()
                    env.close()
                row["declared_over_rulesim"] = row["declared"]["median"] / row["rulesim"]["median"]
                rows.append(row)
    return rows


def team_scenario(agents: int) -> Scenario:
    """GridWar's base game with `agents` a team on the default map, every agent on its base: what war.toml
    plays at every team size (its advanced game plays one agent a team, war.toml's [env.require])."""
    base = builtin_scenario("base")
    if agents == 1:
        return base
    return replace(base, name=f"base-{agents}v{agents}", agents_per_team=agents, red_starts=None,
                   blue_starts=None)


class SpecLoop:
    """A batch of the spec's worlds stepped as sims.Loop steps a simulator: fixed-seed random actions of
    every red agent (the spec's rules play blue), every agent's observation and reward read, finished worlds
    restarted, and (with `trace`) the change log taken at the tracer's cadence."""

    def __init__(self, worlds: DeclaredWorlds, trace: bool, seed: int = 0) -> None:
        self.worlds, self.trace = worlds, trace
        self.rng = np.random.default_rng(seed)
        self._steps_waiting = 0
        worlds.use_generators([np.random.default_rng(seed + i) for i in range(worlds.n_worlds)])
        worlds.engine.trace_on[:] = trace
        worlds.engine.take_trace()
        worlds.reset(np.arange(worlds.n_worlds))

    def run(self, steps: int) -> None:
        w = self.worlds
        red = self.rng.integers(0, w.n_actions, (steps, w.n_worlds, w.n_agents))
        for i in range(steps):
            w.step(red[i])
            for agent in range(w.n_agents):
                w.observations(agent)
                w.rewards(agent)
            done = w.terminated() | w.truncated(None)
            ended = bool(done.any())
            if self.trace:
                self._steps_waiting += 1
                if handover_due(w, self._steps_waiting, ended):  # type: ignore[arg-type]
                    self._steps_waiting = 0
                    w.engine.take_trace()
            if ended:
                w.reset(np.flatnonzero(done))


def spec_rates(agents: list[int], worlds: list[int], repeats: int, target_s: float) -> list[dict[str, Any]]:
    """One row per (agents, worlds): GridWar's base game at that team size (team_scenario) through RefSim,
    RuleSim (sims.Loop) and the spec path (SpecLoop: DeclaredWorlds over war.toml, the engine and reads in
    one compiled call), traced and untraced, as env-steps per CPU second (cpu_rates) and as ratios to RefSim."""
    rows = []
    for n in agents:
        sc = team_scenario(n)
        path, params = scenario_spec(sc)
        spec = load_spec(path, **params)
        for w in worlds:
            row: dict[str, Any] = {"scenario": sc.name, "agents": n, "worlds": w}
            row["reference"] = cpu_rates(Loop(RefSim(sc, w, seed=0), False).run, w, repeats, target_s)
            rules = RuleSim(sc, w, seed=0, trace=True)
            for trace in (False, True):
                row[f"rulesim_{'on' if trace else 'off'}"] = cpu_rates(Loop(rules, trace).run, w, repeats, target_s)
            del rules
            try:
                declared = DeclaredWorlds(spec, w)
            except SpecTooBig as e:  # the batch's memory bound (TRACELAB_SPEC_MEMORY raises it)
                row["spec_skipped"] = str(e)
                declared = None
            if declared is not None:
                row["spec_kernel"] = declared.kernel
                for trace in (False, True):
                    row[f"spec_{'on' if trace else 'off'}"] = cpu_rates(SpecLoop(declared, trace).run, w, repeats,
                                                                         target_s)
                del declared
            ref = row["reference"]["median"]
            for k in ("rulesim_off", "rulesim_on", "spec_off", "spec_on"):
                if k in row:
                    row[f"{k}_over_reference"] = row[k]["median"] / ref
            rows.append(row)
    return rows


def cpu_rates(run: Any, worlds: int, repeats: int, target_s: float) -> dict[str, Any]:
    """Env-steps per CPU second of run(k) (k steps of `worlds` worlds): a calibrated block, a warm-up, then
    `repeats` blocks timed by this process's CPU time (on this shared machine the wall clock also counts the
    turns of other processes, which differ from one block to the next)."""
    block = calibrate(run, target_s)
    run(block)
    rates_ = []
    for _ in range(max(1, repeats)):
        c0 = time.process_time()
        run(block)
        rates_.append(block * worlds / max(time.process_time() - c0, 1e-9))
    return summarize(rates_).to_dict()


def _engine_of(env: Any) -> Any:
    """The engine an env steps (RuleSim's, a declared world's or batch's), its change log switched on."""
    eng = env.sim.engine if hasattr(env, "sim") else (env.world if hasattr(env, "world") else env.worlds).engine
    eng.trace_on[:] = True
    return eng


def _single_runner(env: Any, traced: Any = None) -> Any:
    """Random actions through `env`; `traced`: the engine whose change log is taken after every step."""
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    n = int(env.action_space.n)

    def run(k: int) -> None:
        for a in rng.integers(0, n, k):
            _, _, terminated, truncated, _ = env.step(int(a))
            if traced is not None:
                traced.take_trace()
            if terminated or truncated:
                env.reset()
    return run


def _vector_runner(venv: Any, traced: Any = None) -> Any:
    rng = np.random.default_rng(0)
    venv.reset(seed=0)
    shape = venv.action_space.shape
    high = venv.single_action_space.n if hasattr(venv.single_action_space, "n") else \
        venv.single_action_space.nvec

    def run(k: int) -> None:
        for a in rng.integers(0, high, (k, *shape)):
            venv.step(a)  # same-step autoreset
            if traced is not None:
                traced.take_trace()
    return run


def run(quick: bool = False, repeats: int = 5, agents: list[int] | None = None,
        batch: int | None = None, kernel: str = "auto") -> dict[str, Any]:
    """Every env figure: team sizes `agents` (default 1, 5, 20; quick 1, 2), one world and `batch`
    worlds (default 256; quick 16)."""
    info = machine_info()
    batch = batch or (16 if quick else 256)
    target_s = 0.1 if quick else 1.0
    rows = sim_rates(agents or ([1, 2] if quick else [1, 5, 20]), sorted({1, batch}), repeats, target_s, kernel)
    gym = gym_rates(batch, repeats, target_s)
    declared = declared_rates(batch, repeats, target_s)
    teams = spec_rates(agents or ([1, 2] if quick else [1, 5, 20]), sorted({1, batch}), repeats, target_s)
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "batched_worlds": batch, "sims": rows,
            "goals": goals(rows), "gym": gym, "declared": declared, "spec_teams": teams}


def report(r: dict[str, Any]) -> str:
    med = lambda d: d["steps_per_s"]["median"]  # noqa: E731
    env = lambda d: d["env_steps_per_s"]["median"]  # noqa: E731
    sp = lambda d: f"{100 * d['steps_per_s']['spread']:.0f}%"  # noqa: E731
    sims = format_table(
        ["agents", "worlds", "kernel", "reference env-steps/s", "rules off", "rules on", "rules/ref off",
         "rules/ref on", "spread ref/off/on"],
        [[s["agents"], s["worlds"], s["rules_kernel"], env(s["reference"]), env(s["rules_trace_off"]),
          env(s["rules_trace_on"]),
          s["rules_over_reference"], s["rules_traced_over_reference"],
          "/".join(sp(s[k]) for k in ("reference", "rules_trace_off", "rules_trace_on"))] for s in r["sims"]])
    alone = format_table(
        ["agents", "worlds", "trace", "loop env-steps/s", "engine alone env-steps/s", "engine share"],
        [[s["agents"], s["worlds"], on, env(s[f"rules_trace_{on}"]), env(s["engine_only"][f"trace_{on}"]),
          env(s[f"rules_trace_{on}"]) / env(s["engine_only"][f"trace_{on}"])]
         for s in r["sims"] if "engine_only" in s for on in ("off", "on")])
    goals_t = format_table(["goal", "target", "measured", "engine alone", "result"],
                           [[g["goal"], g["target"], f"{fmt_num(g['measured'])} {g['unit']}",
                             f"{fmt_num(g['engine_alone'])} {g['unit']}" if "engine_alone" in g else "",
                             "met" if g["met"] else "not met"] for g in r["goals"]])
    g = r["gym"]
    gym_t = f"gymnasium ({g['env_id']}: the declared env, tracing off)\n" + format_table(
        ["backend", "env", "worlds", "steps/s", "env-steps/s", "spread"],
        [[x["backend"], x["kind"], x["worlds"], med(x), env(x) if "env_steps_per_s" in x else med(x), sp(x)]
         for x in g["rows"]])
    measured = [d for d in r.get("declared", []) if "skipped" not in d]
    declared = "GridWar 1v1 through RuleSim and through its declared spec (rules/gridworld/war.toml; " \
               "traced: the engine's change log on)\n" + format_table(
                   ["scenario", "env", "worlds", "trace", "RuleSim env-steps/s", "declared env-steps/s",
                    "declared/RuleSim", "spread RuleSim/declared"],
                   [[d["scenario"], d["kind"], d["worlds"], "on" if d["trace"] else "off",
                     d["rulesim"]["median"], d["declared"]["median"], d["declared_over_rulesim"],
                     f"{100 * d['rulesim']['spread']:.0f}%/{100 * d['declared']['spread']:.0f}%"]
                    for d in measured]) + "".join(
                   f"\nnot measured: {d['spec']}: {d['skipped']}" for d in r.get("declared", []) if "skipped" in d)
    teams = "GridWar's base game by team size: RefSim, RuleSim and the spec path (war.toml, every red agent " \
            "playing), env-steps per CPU second and /RefSim\n" + format_table(
                ["scenario", "worlds", "spec kernel", "RefSim", "RuleSim off", "RuleSim on", "spec off", "spec on",
                 "RuleSim/ref off/on", "spec/ref off/on", "spread ref/spec off/on"],
                [[t["scenario"], t["worlds"], t["spec_kernel"], t["reference"]["median"], t["rulesim_off"]["median"],
                  t["rulesim_on"]["median"], t["spec_off"]["median"], t["spec_on"]["median"],
                  f"{t['rulesim_off_over_reference']:.3f}/{t['rulesim_on_over_reference']:.3f}",
                  f"{t['spec_off_over_reference']:.3f}/{t['spec_on_over_reference']:.3f}",
                  "/".join(f"{100 * t[k]['spread']:.0f}%" for k in ("reference", "spec_off", "spec_on"))]
                 for t in r.get("spec_teams", []) if "spec_skipped" not in t]) + "".join(
                f"\nspec path not measured: {t['scenario']} x{t['worlds']}: {t['spec_skipped']}"
                for t in r.get("spec_teams", []) if "spec_skipped" in t)
    return "\n\n".join([machine_line(r["machine"], r["quick"], r["repeats"]),
                        "simulators (env-steps/s = steps/s x worlds)\n" + sims,
                        "the engine alone, replaying the loop's steps (share = loop / engine alone)\n" + alone,
                        goals_t, gym_t, declared, teams])
