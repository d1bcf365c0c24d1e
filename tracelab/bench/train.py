"""`tracelab bench train`: training transitions/s end to end with the method's defaults (1v1 base, rules
backend, one update per transition, live logging into a run), and beside it, in the same process: the
update alone (tracelab's fused update, and the textbook autograd + torch.optim.Adam update of the same
network and batch) and the env alone. The loop's share = 1 - (update time / training-step time).
Goals (docs/benchmarks.md, "Training"): loop around the update <= 15% of a step; >= 5,000 transitions/s."""
from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.bench.common import fmt_num, format_table, machine_info, median_of, rates
from tracelab.bench.engine import machine_line

GOAL_TRANSITIONS_PER_S = 5_000
GOAL_LOOP_SHARE = 0.15


def _config(envs: int, threads: int) -> Any:
    from tracelab.train.config import TrainConfig
    # the method's defaults; no evaluations or checkpoints inside the timed blocks
    return TrainConfig(scenario="base", steps=10_000_000, envs=envs, threads=threads, eval_every=0,
                       checkpoint_every=0)


def end_to_end(envs: int, threads: int, block: int, repeats: int, run_dir: Path) -> dict[str, Any]:
    """Transitions/s of Trainer.train over blocks of `block` steps after warm-up, logging into a run."""
    from tracelab.game.scenario import builtin_scenario
    from tracelab.store import TraceWriter
    from tracelab.train.loop import Trainer
    cfg = _config(envs, threads)
    writer = TraceWriter.open(run_dir, {"command": "tracelab bench train", "config": cfg.to_dict()})
    trainer = Trainer(cfg, builtin_scenario("base"), writer)
    try:
        trainer.train(stop_at=cfg.warmup + 2 * cfg.batch + block)  # past warm-up: updates run from here
        durations = median_of(lambda: trainer.train(stop_at=trainer.step + block), repeats)
        updates = sum(lr.updates for lr in trainer.learners.values())
    finally:
        trainer.close()
        writer.close()
    return {"envs": envs, "block_steps": block, "transitions_per_s": rates(durations, block).to_dict(),
            "updates_done": updates}


def _filled_learner(threads: int) -> Any:
    import torch

    from tracelab.train.learner import DQNLearner
    from tracelab.train.network import Shape
    torch.set_num_threads(threads)
    cfg = _config(1, threads)
    shape = Shape(4, cfg.hidden, 5)
    learner = DQNLearner(shape, lr=cfg.lr, batch=cfg.batch, buffer=cfg.buffer,
                         generator=torch.Generator().manual_seed(0))
    rng = np.random.default_rng(0)
    k = 10_000
    learner.buffer.add(rng.integers(0, 8, (k, 4)).astype(np.float32), rng.integers(0, 5, k),
                       rng.normal(size=k).astype(np.float32), rng.integers(0, 8, (k, 4)).astype(np.float32),
                       np.full(k, cfg.gamma, np.float32))
    return learner


def update_rate(threads: int, n: int, repeats: int) -> dict[str, Any]:
    """tracelab's update (sampling included) on the method's network and batch."""
    learner = _filled_learner(threads)
    rng = np.random.default_rng(1)

    def run() -> None:
        for _ in range(n):
            learner.update(rng)
    run()
    return rates(median_of(run, repeats), n).to_dict()


def textbook_update_rate(threads: int, n: int, repeats: int) -> dict[str, Any]:
    """The same update as autograd + nn.Sequential + torch.optim.Adam (foreach) would run it."""
    import torch
    learner = _filled_learner(threads)
    cfg = _config(1, threads)
    make = lambda: torch.nn.Sequential(torch.nn.Linear(4, cfg.hidden), torch.nn.Tanh(),  # noqa: E731
                                       torch.nn.Linear(cfg.hidden, 5))
    net, target = make(), make()
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    b = learner.buffer
    s, s2 = torch.from_numpy(b.b_obs[0, :, :-1]), torch.from_numpy(b.b_obs[1, :, :-1])
    a, r, d = torch.from_numpy(b.b_action), torch.from_numpy(b.b_reward), torch.from_numpy(b.b_discount)
    rng = np.random.default_rng(1)

    def run() -> None:
        for _ in range(n):
            b.sample(rng)
            q = net(s).gather(1, a)
            with torch.no_grad():
                y = r + d * target(s2).max(1, keepdim=True).values
            loss = torch.nn.functional.smooth_l1_loss(q, y)
            opt.zero_grad()
            loss.backward()
            opt.step()
    run()
    return rates(median_of(run, repeats), n).to_dict()


def env_rate(envs: int, n: int, repeats: int) -> dict[str, Any]:
    """World-steps/s of the batched env alone (random actions, rules backend, no trace)."""
    from tracelab.envs.vector_env import GridWarVectorEnv
    env = GridWarVectorEnv(envs, "base", backend="rules")
    env.reset(seed=0)
    acts = np.random.default_rng(0).integers(0, 5, (n, envs))

    def run() -> None:
        for a in acts:
            env.step(a)
    run()
    out = rates(median_of(run, repeats), n * envs).to_dict()
    env.close()
    return out


def run(quick: bool = False, repeats: int = 5, envs: int = 16, threads: int = 1) -> dict[str, Any]:
    info = machine_info()
    block = 512 if quick else 8_192
    n_upd = 100 if quick else 2_000
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-train-") as tmp:
        e2e = end_to_end(envs, threads, block, repeats, Path(tmp) / "run")
    upd = update_rate(threads, n_upd, repeats)
    textbook = textbook_update_rate(threads, n_upd, repeats)
    env = env_rate(envs, max(10, block // envs), repeats)
    t_step = 1.0 / e2e["transitions_per_s"]["median"]
    t_update = 1.0 / upd["median"]
    t_env = 1.0 / env["median"]
    loop_share = 1.0 - t_update / t_step
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "envs": envs, "threads": threads,
            "end_to_end": e2e, "update_per_s": upd, "textbook_update_per_s": textbook, "env_steps_per_s": env,
            "step_us": 1e6 * t_step, "update_us": 1e6 * t_update, "env_us": 1e6 * t_env,
            "loop_share": loop_share, "rest_share": 1.0 - (t_update + t_env) / t_step,
            "goals": [{"goal": "loop around the update", "target": f"<= {100 * GOAL_LOOP_SHARE:.0f}% of a step",
                       "measured": f"{100 * loop_share:.0f}%", "met": loop_share <= GOAL_LOOP_SHARE},
                      {"goal": "transitions/s, one update each",
                       "target": f">= {GOAL_TRANSITIONS_PER_S:,}",
                       "measured": fmt_num(e2e["transitions_per_s"]["median"]),
                       "met": e2e["transitions_per_s"]["median"] >= GOAL_TRANSITIONS_PER_S}]}


def report(r: dict[str, Any]) -> str:
    sp = lambda d: f"{100 * d['spread']:.0f}%"  # noqa: E731
    e2e = r["end_to_end"]["transitions_per_s"]
    rows = [["training end to end (transitions/s, 1 update each)", e2e["median"], sp(e2e), r["step_us"]],
            ["update alone, tracelab's fused (updates/s)", r["update_per_s"]["median"], sp(r["update_per_s"]),
             r["update_us"]],
            ["update alone, autograd + torch.optim.Adam (updates/s)", r["textbook_update_per_s"]["median"],
             sp(r["textbook_update_per_s"]), 1e6 / r["textbook_update_per_s"]["median"]],
            [f"env alone, {r['envs']} worlds (world-steps/s)", r["env_steps_per_s"]["median"],
             sp(r["env_steps_per_s"]), r["env_us"]]]
    shares = (f"per transition: update {r['update_us']:.0f} µs, env {r['env_us']:.0f} µs, the rest (buffer, "
              f"ε, transitions, logging) {r['step_us'] - r['update_us'] - r['env_us']:.0f} µs; loop around the "
              f"update {100 * r['loop_share']:.0f}% of a step (env included), the rest alone "
              f"{100 * r['rest_share']:.0f}%")
    goals = format_table(["goal", "target", "measured", "result"],
                         [[g["goal"], g["target"], g["measured"], "met" if g["met"] else "not met"]
                          for g in r["goals"]])
    head = (f"1v1 base, rules backend, method's DQN defaults (64 tanh, batch 128, Adam 5e-4), "
            f"{r['envs']} worlds, torch threads {r['threads']}, live logging into a run")
    table = format_table(["figure", "median", "spread", "µs each"], rows)
    return "\n\n".join([machine_line(r["machine"], r["quick"], r["repeats"]), head, table, shares, goals])

