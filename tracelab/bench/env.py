"""`tracelab bench env`: the war game through its spec (rules/gridworld/war.toml's base game, every red agent
playing, on DeclaredWorlds: tracelab.bench.sims) beside RefSim, the hand-written oracle, by team size, one world
and batched, traced and untraced, as env-steps per CPU second and ratios to RefSim (issue 38's speed points);
then its registered id through gymnasium (gym.make, gym.make_vec). Goals: docs/benchmarks.md."""
from __future__ import annotations

from typing import Any

import numpy as np

from tracelab.bench.common import block_rates, fmt_num, format_table, machine_info, summarize
from tracelab.bench.engine import GOAL_STEPS_PER_S, machine_line
from tracelab.bench.sims import RefLoop, SpecLoop, cpu_rates, team_scenario, team_spec
from tracelab.envs.declared.gridwar import ADVANCED_ID
from tracelab.envs.declared.spec_size import SpecTooBig
from tracelab.envs.declared.vector_world import DeclaredWorlds
from tracelab.game.refsim import RefSim

# deferred: gymnasium loads in the section that measures it

GOAL_BATCHED_ENV_STEPS_PER_S = 1_000_000  # batched, tracing off
GOAL_MAX_SLOWDOWN = 5.0  # rule-driven within 5x of the hand-written simulator
ENV_ID = ADVANCED_ID


def spec_rates(agents: list[int], worlds: list[int], repeats: int, target_s: float,
               kernel: str = "auto") -> list[dict[str, Any]]:
    """One row per (agents, worlds): war.toml's base game at that team size through RefSim (RefLoop) and the
    spec path (SpecLoop, engine kernel `kernel`), traced and untraced, as env-steps per CPU second and as
    ratios to RefSim."""
    rows = []
    for n in agents:
        spec = team_spec(n)
        for w in worlds:
            row: dict[str, Any] = {"scenario": team_scenario(n).name, "agents": n, "worlds": w}
            row["reference"] = cpu_rates(RefLoop(RefSim(team_scenario(n), w, seed=0)).run, w, repeats, target_s)
            try:
                declared = DeclaredWorlds(spec, w, kernel)
            except SpecTooBig as e:  # the batch's memory bound (TRACELAB_SPEC_MEMORY raises it)
                row["spec_skipped"] = str(e)
                rows.append(row)
                continue
            row["spec_kernel"] = declared.kernel
            for trace in (False, True):
                row[f"spec_{'on' if trace else 'off'}"] = cpu_rates(SpecLoop(declared, trace).run, w, repeats,
                                                                     target_s)
            del declared  # batched worlds of big teams hold much memory
            ref = row["reference"]["median"]
            for k in ("spec_off", "spec_on"):
                row[f"{k}_over_reference"] = row[k]["median"] / ref
            rows.append(row)
    return rows


def goals(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The three goals of the spec path with the measured value and met / not met (per CPU second)."""
    measured = [r for r in rows if "spec_skipped" not in r]
    single = next(r for r in measured if r["agents"] == 1 and r["worlds"] == 1)
    batched = max((r for r in measured if r["agents"] == 1), key=lambda r: r["worlds"])
    slow = min(measured, key=lambda r: r["spec_off_over_reference"])
    traced = single["spec_on"]["median"]
    env_steps = batched["spec_off"]["median"]
    slowdown = 1 / slow["spec_off_over_reference"]
    return [
        {"goal": "spec path single 1v1, tracing on", "target": f">= {GOAL_STEPS_PER_S:,} steps/s",
         "measured": traced, "unit": "steps/CPU s", "met": traced >= GOAL_STEPS_PER_S},
        {"goal": f"spec path batched 1v1 ({batched['worlds']} worlds), tracing off",
         "target": f">= {GOAL_BATCHED_ENV_STEPS_PER_S:,} env-steps/s", "measured": env_steps,
         "unit": "env-steps/CPU s", "met": env_steps >= GOAL_BATCHED_ENV_STEPS_PER_S},
        {"goal": f"spec path within {GOAL_MAX_SLOWDOWN:g}x of RefSim (worst: {slow['agents']} agents, "
                 f"{slow['worlds']} worlds, tracing off)",
         "target": f"<= {GOAL_MAX_SLOWDOWN:g}x slower", "measured": slowdown, "unit": "x slower",
         "met": slowdown <= GOAL_MAX_SLOWDOWN},
    ]


def gym_rates(worlds: int, repeats: int, target_s: float) -> dict[str, Any]:
    """Steps/s through gymnasium: the single env (gymnasium.make, 1v1) and the vector env (`worlds`
    worlds, gymnasium.make_vec) of war.toml's id, the declared spec's, tracing off."""
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


def _single_runner(env: Any) -> Any:
    """Random actions through `env`, reset when an episode ends."""
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    n = int(env.action_space.n)

    def run(k: int) -> None:
        for a in rng.integers(0, n, k):
            _, _, terminated, truncated, _ = env.step(int(a))
            if terminated or truncated:
                env.reset()
    return run


def _vector_runner(venv: Any) -> Any:
    rng = np.random.default_rng(0)
    venv.reset(seed=0)
    shape = venv.action_space.shape
    high = venv.single_action_space.n if hasattr(venv.single_action_space, "n") else \
        venv.single_action_space.nvec

    def run(k: int) -> None:
        for a in rng.integers(0, high, (k, *shape)):
            venv.step(a)  # same-step autoreset
    return run


def run(quick: bool = False, repeats: int = 5, agents: list[int] | None = None,
        batch: int | None = None, kernel: str = "auto") -> dict[str, Any]:
    """Every env figure: team sizes `agents` (default 1, 5, 20; quick 1, 2), one world and `batch`
    worlds (default 256; quick 16)."""
    info = machine_info()
    batch = batch or (16 if quick else 256)
    target_s = 0.1 if quick else 1.0
    teams = spec_rates(agents or ([1, 2] if quick else [1, 5, 20]), sorted({1, batch}), repeats, target_s, kernel)
    gym = gym_rates(batch, repeats, target_s)
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "batched_worlds": batch, "spec_teams": teams,
            "goals": goals(teams), "gym": gym}


def report(r: dict[str, Any]) -> str:
    med = lambda d: d["steps_per_s"]["median"]  # noqa: E731
    env = lambda d: d["env_steps_per_s"]["median"]  # noqa: E731
    sp = lambda d: f"{100 * d['steps_per_s']['spread']:.0f}%"  # noqa: E731
    teams = "war.toml's base game by team size: RefSim and the spec path (war.toml, every red agent playing), " \
            "env-steps per CPU second and /RefSim\n" + format_table(
                ["scenario", "worlds", "spec kernel", "RefSim", "spec off", "spec on", "spec/ref off", "spec/ref on",
                 "spread ref/spec off/on"],
                [[t["scenario"], t["worlds"], t["spec_kernel"], t["reference"]["median"], t["spec_off"]["median"],
                  t["spec_on"]["median"], f"{t['spec_off_over_reference']:.3f}", f"{t['spec_on_over_reference']:.3f}",
                  "/".join(f"{100 * t[k]['spread']:.0f}%" for k in ("reference", "spec_off", "spec_on"))]
                 for t in r["spec_teams"] if "spec_skipped" not in t]) + "".join(
                f"\nspec path not measured: {t['scenario']} x{t['worlds']}: {t['spec_skipped']}"
                for t in r["spec_teams"] if "spec_skipped" in t)
    goals_t = format_table(["goal", "target", "measured", "result"],
                           [[g["goal"], g["target"], f"{fmt_num(g['measured'])} {g['unit']}",
                             "met" if g["met"] else "not met"] for g in r["goals"]])
    g = r["gym"]
    gym_t = f"gymnasium ({g['env_id']}: the declared env, tracing off)\n" + format_table(
        ["backend", "env", "worlds", "steps/s", "env-steps/s", "spread"],
        [[x["backend"], x["kind"], x["worlds"], med(x), env(x) if "env_steps_per_s" in x else med(x), sp(x)]
         for x in g["rows"]])
    return "\n\n".join([machine_line(r["machine"], r["quick"], r["repeats"]), teams, goals_t, gym_t])
