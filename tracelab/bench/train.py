"""`tracelab bench train`: training transitions/s end to end with the method's defaults (1v1 base through
war.toml, as `tracelab train --scenario base` trains it: EnvTrainer, one update per transition, live
logging into a run) with the fused learner and with the readable one (tracelab/train/dqn.py), and beside
them, in the same process: the update alone (the fused learner's, the readable learner's, and the textbook
autograd + torch.optim.Adam update of the same network and batch written inline) and the spec's batched env
alone. The loop's share = 1 - (update time / training-step time).
Goals (docs/benchmarks/history.md, "Training"): loop around the update <= 15% of a step; >= 5,000 transitions/s;
the fused update >= 4x the textbook one. Beside them, 5v5 base end to end (every agent a row of the shared
network), in world-steps per CPU second."""
from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tracelab.bench.common import fmt_num, format_table, machine_info, summarize
from tracelab.bench.engine import machine_line
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.gridwar_scenarios import ScenarioTraining
from tracelab.game.scenario import builtin_scenario
from tracelab.store import TraceWriter
from tracelab.train.config import TrainConfig
from tracelab.train.env_policy import make_vector_env
from tracelab.train.env_trainer import EnvTrainer
from tracelab.train.qnet import NetSpec
from tracelab.train.train_loop import make_learner

GOAL_TRANSITIONS_PER_S = 5_000
GOAL_LOOP_SHARE = 0.15
GOAL_FUSED_OVER_TEXTBOOK = 4.0


def _config(envs: int, threads: int, learner: str = "fused") -> Any:
    # the method's defaults; no evaluations or checkpoints inside the timed blocks
    return TrainConfig(steps=10_000_000, envs=envs, threads=threads, eval_every=0,
                       checkpoint_every=0, learner=learner)


TEAM = 5  # the team size of the 5v5 figure


def _base_source() -> EnvSource:
    """The env `tracelab train --scenario base` trains on (its spec id)."""
    return ScenarioTraining.of(builtin_scenario("base")).source


class EndToEnd:
    """An EnvTrainer on the 1v1 base game with the method's defaults logging into a run, past its warm-up;
    `run(k)` trains k more steps through EnvTrainer.train (logging, ε, replay, updates: everything but
    evaluations). `team`: TEAM agents a team."""

    def __init__(self, envs: int, threads: int, run_dir: Path, learner: str, team: bool = False) -> None:
        cfg = _config(envs, threads, learner)
        self.writer = TraceWriter.open(run_dir, {"command": "tracelab bench train", "config": cfg.to_dict()})
        source = _base_source()
        if team:
            source = EnvSource(source.name, {**source.kwargs, "agents_per_team": TEAM})
        self.trainer = EnvTrainer(cfg, source, self.writer)
        self.trainer.train(stop_at=cfg.warmup + 2 * cfg.batch)  # updates run from here on

    def run(self, k: int) -> None:
        self.trainer.train(stop_at=self.trainer.step + k)

    def close(self) -> None:
        self.trainer.close()
        self.writer.close()


def _filled_learner(threads: int, learner: str = "fused") -> Any:
    torch.set_num_threads(threads)
    cfg = _config(1, threads, learner)
    learner = make_learner(learner, NetSpec(4, cfg.hidden_sizes, 5), cfg, torch.Generator().manual_seed(0))
    rng = np.random.default_rng(0)
    k = 10_000
    learner.buffer.add(rng.integers(0, 8, (k, 4)).astype(np.float32), rng.integers(0, 5, k),
                       rng.normal(size=k).astype(np.float32), rng.integers(0, 8, (k, 4)).astype(np.float32),
                       np.full(k, cfg.gamma, np.float32))
    return learner


def learner_updates(threads: int, learner: str) -> Callable[[int], None]:
    """A learner's update (sampling included) on the method's network and batch: run(k) makes k."""
    learner = _filled_learner(threads, learner)
    rng = np.random.default_rng(1)

    def run(k: int) -> None:
        for _ in range(k):
            learner.update(rng)
    return run


def textbook_updates(threads: int) -> Callable[[int], None]:
    """The same update as autograd + nn.Sequential + torch.optim.Adam (foreach) would run it."""
    learner = _filled_learner(threads)
    cfg = _config(1, threads)
    h = cfg.hidden_sizes[0]
    make = lambda: torch.nn.Sequential(torch.nn.Linear(4, h), torch.nn.Tanh(), torch.nn.Linear(h, 5))  # noqa: E731
    net, target = make(), make()
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    b = learner.buffer
    s, s2, r, d = (torch.from_numpy(x) for x in (b.b_obs[0, :, :-1], b.b_obs[1, :, :-1], b.b_reward,
                                                  b.b_discount))  # read-only views of the batch
    rng = np.random.default_rng(1)

    def run(k: int) -> None:
        for _ in range(k):
            b.sample(rng)
            a = torch.from_numpy(b.sampled_actions())
            q = net(s).gather(1, a)
            with torch.no_grad():
                y = r + d * target(s2).max(1, keepdim=True).values
            loss = torch.nn.functional.smooth_l1_loss(q, y)
            opt.zero_grad()
            loss.backward()
            opt.step()
    return run


def env_steps(envs: int) -> tuple[Callable[[int], None], Any]:
    """The batched env the trainer steps, alone (random actions, no trace): run(k) makes k passes."""
    env, _ = make_vector_env(_base_source(), envs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)

    def run(k: int) -> None:
        for a in rng.integers(0, env.single_action_space.n, (k, envs)):
            env.step(a)
    return run, env


def _timed(fn: Callable[[int], None], k: int) -> tuple[float, float]:
    """(wall-clock s, CPU s of this process) of fn(k). On a shared machine the CPU time says what the
    work costs; the wall clock also counts the time other processes held the cores."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn(k)
    return time.perf_counter() - t0, time.process_time() - c0


def run(quick: bool = False, repeats: int = 5, envs: int = 64, threads: int = 1) -> dict[str, Any]:
    """The four figures, measured round by round (one block of each per round) so that each round's
    ratios compare figures taken under the same machine load; medians over the rounds."""
    info = machine_info()
    block = 512 if quick else 4_096   # training steps per end-to-end block
    n_upd = 100 if quick else 1_000   # updates per update block
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-train-") as tmp:
        e2e = EndToEnd(envs, threads, Path(tmp) / "run", "fused")
        e2e_readable = EndToEnd(envs, threads, Path(tmp) / "run-readable", "readable")
        team = EndToEnd(envs, threads, Path(tmp) / "run-5v5", "fused", team=True)
        fused, readable = learner_updates(threads, "fused"), learner_updates(threads, "readable")
        textbook = textbook_updates(threads)
        env_run, env = env_steps(envs)
        passes = max(4, block // envs)
        for fn, k in ((fused, 20), (readable, 20), (textbook, 20), (env_run, 20)):
            fn(k)  # warm-up
        rounds: dict[str, list[float]] = {"e2e": [], "e2e_readable": [], "fused": [], "readable": [],
                                          "textbook": [], "env": [], "team": []}
        cpu: dict[str, list[float]] = {k: [] for k in rounds}
        try:
            for _ in range(repeats):
                for key, fn, k, units in (("e2e", e2e.run, block, block),
                                          ("e2e_readable", e2e_readable.run, block, block),
                                          ("fused", fused, n_upd, n_upd), ("readable", readable, n_upd, n_upd),
                                          ("textbook", textbook, n_upd, n_upd),
                                          ("env", env_run, passes, passes * envs),
                                          ("team", team.run, block // 4, block // 4)):
                    wall, used = _timed(fn, k)
                    rounds[key].append(units / wall)
                    cpu[key].append(units / max(used, 1e-9))
        finally:
            e2e.close()
            e2e_readable.close()
            team.close()
            env.close()
    loop_shares = [1.0 - f_e2e / f_upd for f_e2e, f_upd in zip(rounds["e2e"], rounds["fused"])]
    rest_shares = [1.0 - f_e2e / f_upd - f_e2e / f_env
                   for f_e2e, f_upd, f_env in zip(rounds["e2e"], rounds["fused"], rounds["env"])]
    speedups = [f / t for f, t in zip(rounds["fused"], rounds["textbook"])]
    over_readable = [f / t for f, t in zip(rounds["fused"], rounds["readable"])]
    e2e_over_readable = [f / t for f, t in zip(rounds["e2e"], rounds["e2e_readable"])]
    e2e_s = summarize(rounds["e2e"])
    loop_share = summarize(loop_shares).median
    speedup = summarize(speedups).median
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "envs": envs, "threads": threads,
            "block_steps": block, "updates_per_block": n_upd,
            "transitions_per_s": e2e_s.to_dict(), "update_per_s": summarize(rounds["fused"]).to_dict(),
            "textbook_update_per_s": summarize(rounds["textbook"]).to_dict(),
            "readable_update_per_s": summarize(rounds["readable"]).to_dict(),
            "readable_transitions_per_s": summarize(rounds["e2e_readable"]).to_dict(),
            "fused_over_readable": summarize(over_readable).to_dict(),
            "e2e_fused_over_readable": summarize(e2e_over_readable).to_dict(),
            "env_steps_per_s": summarize(rounds["env"]).to_dict(),
            "fused_over_textbook": summarize(speedups).to_dict(),
            "loop_share": summarize(loop_shares).to_dict(), "rest_share": summarize(rest_shares).to_dict(),
            "per_cpu_second": {k: summarize(v).to_dict() for k, v in cpu.items()},
            "team": TEAM, "team_per_s": summarize(rounds["team"]).to_dict(),
            "goals": [{"goal": "loop around the update", "target": f"<= {100 * GOAL_LOOP_SHARE:.0f}% of a step",
                       "measured": f"{100 * loop_share:.0f}%", "met": loop_share <= GOAL_LOOP_SHARE},
                      {"goal": "transitions/s, one update each", "target": f">= {GOAL_TRANSITIONS_PER_S:,}",
                       "measured": fmt_num(e2e_s.median), "met": e2e_s.median >= GOAL_TRANSITIONS_PER_S},
                      {"goal": "fused update over the textbook one", "target": f">= {GOAL_FUSED_OVER_TEXTBOOK:g}x",
                       "measured": f"{speedup:.2f}x", "met": speedup >= GOAL_FUSED_OVER_TEXTBOOK}]}


def report(r: dict[str, Any]) -> str:
    sp = lambda d: f"{100 * d['spread']:.0f}%"  # noqa: E731
    us = lambda d: 1e6 / d["median"]  # noqa: E731
    rows = [["training end to end, fused learner (transitions/s, 1 update each)", r["transitions_per_s"]["median"],
             sp(r["transitions_per_s"]), us(r["transitions_per_s"])],
            ["training end to end, readable learner (transitions/s)", r["readable_transitions_per_s"]["median"],
             sp(r["readable_transitions_per_s"]), us(r["readable_transitions_per_s"])],
            ["update alone, fused learner (updates/s)", r["update_per_s"]["median"], sp(r["update_per_s"]),
             us(r["update_per_s"])],
            ["update alone, readable learner, dqn.py (updates/s)", r["readable_update_per_s"]["median"],
             sp(r["readable_update_per_s"]), us(r["readable_update_per_s"])],
            ["update alone, autograd + torch.optim.Adam (updates/s)", r["textbook_update_per_s"]["median"],
             sp(r["textbook_update_per_s"]), us(r["textbook_update_per_s"])],
            [f"env alone, {r['envs']} worlds (world-steps/s)", r["env_steps_per_s"]["median"],
             sp(r["env_steps_per_s"]), us(r["env_steps_per_s"])]]
    rows.append([f"{r['team']}v{r['team']} base end to end, fused learner (world-steps/s)", r["team_per_s"]["median"],
                 sp(r["team_per_s"]), us(r["team_per_s"])])
    shares = (f"medians of per-round ratios: fused update {r['fused_over_textbook']['median']:.2f}x the "
              f"textbook one, {r['fused_over_readable']['median']:.2f}x the readable learner's; end to end, "
              f"fused {r['e2e_fused_over_readable']['median']:.2f}x readable; the loop around the update "
              f"{100 * r['loop_share']['median']:.0f}% of a training step (env included), the rest "
              f"(buffer, ε, transitions, logging) "
              f"{100 * r['rest_share']['median']:.0f}%")
    goals = format_table(["goal", "target", "measured", "result"],
                         [[g["goal"], g["target"], g["measured"], "met" if g["met"] else "not met"]
                          for g in r["goals"]])
    head = (f"1v1 base through war.toml (EnvTrainer), method's DQN defaults (64 tanh, batch 128, Adam 5e-4), "
            f"{r['envs']} worlds, torch threads {r['threads']}, live logging into a run; "
            f"{r['repeats']} rounds of {r['block_steps']:,} training steps, {r['updates_per_block']:,} updates "
            f"of each kind, and env steps")
    pc = r["per_cpu_second"]
    for row, key in zip(rows, ("e2e", "e2e_readable", "fused", "readable", "textbook", "env", "team")):
        row.append(pc[key]["median"])
    table = format_table(["figure", "median", "spread", "µs each", "per CPU-second"], rows)
    cpu_note = ("per CPU-second: the same work per second of this process's CPU time (all its threads), "
                "what the wall clock would show with the cores to itself")
    return "\n\n".join([machine_line(r["machine"], r["quick"], r["repeats"]), head, table, cpu_note, shares,
                         goals])
