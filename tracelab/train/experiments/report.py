"""The markdown report of an experiment and its PNG plots: the command, commit, machine, wall time,
opponent settings, every seed's final evaluation counted both ways, the spread over seeds, the goal."""
from __future__ import annotations

import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.train.experiments import plots
from tracelab.train.config import TrainConfig
from tracelab.train.experiments.run import (TRAIN_P, ExperimentResult, action_names, arm_world, commit, eval_ps, is_world,
                                           machine, trainer_note, train_config)
from tracelab.train.experiments.runner import METHOD_CUT, EvalFigures, curves, p_suffix, run_sql
from tracelab.train.experiments.stats import spread, wilson
from tracelab.train.reward_scale import METHOD_REWARD_SCALE


# the settings of the method's DQN (docs/training.md, "The command"); a report names those an arm changes
DQN_FIELDS = ("hidden", "lr", "gamma", "batch", "buffer", "target_every", "eps_start", "eps_end",
              "eps_decay_start", "eps_decay_end", "updates_per_step", "reward_scale", "mask", "explore_scripted",
              "slow_every_step", "double_dqn", "dueling")


def _setting(name: str, value: Any) -> str:
    """'lr 0.001', 'hidden 64,64', 'mask' (a flag that is on)."""
    label = name.replace("_", " ")
    if isinstance(value, bool):
        return label
    return f"{label} {value}" if isinstance(value, str) else f"{label} {value:g}"


def learner_text(result: ExperimentResult) -> str:
    """Each arm's departures from the method's DQN settings, and its reward scale either way."""
    method = TrainConfig(reward_scale=METHOD_REWARD_SCALE)   # train's defaults but for the reward scale
    parts = []
    for ar in result.arms:
        cfg = train_config(result.experiment, ar.arm, result.budget, 0)
        changed = [_setting(name, getattr(cfg, name)) for name in DQN_FIELDS
                   if getattr(cfg, name) != getattr(method, name)]
        same_scale = "" if cfg.reward_scale != METHOD_REWARD_SCALE else f", reward scale {METHOD_REWARD_SCALE:g}"
        parts.append(f"{ar.arm.label}: {', '.join(changed) if changed else 'as the method'}{same_scale}")
    return "the method's DQN (docs/training.md), except: " + "; ".join(parts)


def pct(x: float | None) -> str:
    return "-" if x is None or x != x else f"{100 * x:.1f}%"


def num(x: float | None, fmt: str = ".2f") -> str:
    return "-" if x is None or x != x else format(x, fmt)


def spread_text(values: list[float], percent: bool = True) -> str:
    s = spread(values)
    f = (lambda v: f"{100 * v:.1f}%") if percent else (lambda v: f"{v:.2f}")
    text = f"mean {f(s['mean'])}, min-max {f(s['min'])}-{f(s['max'])}"
    if s["n"] > 1:
        lo, hi = (max(0.0, s["ci_low"]), min(1.0, s["ci_high"])) if percent else (s["ci_low"], s["ci_high"])
        text += f", 95% CI of the mean {f(lo)}-{f(hi)}"
    return text + f" ({s['n']} seed{'s' if s['n'] != 1 else ''})"


def write_report(result: ExperimentResult, report_dir: Path) -> Path:
    command = result.command
    exp, budget = result.experiment, result.budget
    fig_dir = report_dir / exp.name
    fig_dir.mkdir(parents=True, exist_ok=True)
    figures = make_plots(result, fig_dir)
    L: list[str] = [f"# {exp.title}", ""]
    if result.quick:
        L += ["**A `--quick` run** (a smoke test of the command: a few steps, one seed, a small evaluation); "
              "its figures say nothing about the method.", ""]
    L += ["| | |", "|---|---|",
          f"| command | `{command}` |",
          f"| commit | `{result.commit or commit()}` |",
          f"| machine | {result.machine or machine()} |",
          f"| wall time | {result.wall_s / 60:.1f} min ({result.wall_s:.0f} s); report written {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} |",
          f"| budget | {budget.seeds} seed{'s' if budget.seeds != 1 else ''} x {budget.steps:,} training steps per "
          f"setting; {budget.eval_games} games per evaluation, {budget.evals} evaluation(s) over training |",
          f"| learner | {learner_text(result)} |",
          f"| trainer | {trainer_note(exp)} |",
          *setting_rows(result),
          f"| runs | `{result.out_dir}` (one training run per seed; `tracelab sql RUN ...`) |", ""]
    L += ["## Result", "", *goal_lines(result), ""]
    L += ["## Final evaluations, per seed", "",
          "Every seed's final policy, greedy, against each opponent setting. Win rate with its 95% Wilson "
          "interval over the games; `method` = the method's counting.", "",
          "| setting | seed | opponent p | games | wins | losses | draws | truncated | win rate | method win rate "
          "[95% CI] | mean return | actions per win (method) |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for ar in result.arms:
        for s in ar.seeds:
            for p, r in s.final.items():
                lo, hi = wilson(r.method_wins, r.games)
                L.append(f"| {ar.arm.label} | {s.seed} | {p_text(result, p)} | {r.games} | {r.wins} | {r.losses} | {r.draws} | "
                         f"{r.truncated} | {pct(r.win_rate)} | {pct(r.method_win_rate)} [{pct(lo)}-{pct(hi)}] | "
                         f"{r.mean_return:.1f} | {num(r.method_actions_per_win)} |")
    L += ["", "Over seeds (method's counting):", ""]
    for ar in result.arms:
        for p in eval_ps(exp):
            vals = [s.final[p].method_win_rate for s in ar.seeds if p in s.final]
            if vals:
                L.append(f"- {ar.arm.label}{against(result, p)}: {spread_text(vals)}"
                         + (f"; the method: {ar.arm.published_note}" if ar.arm.published_note and p == 0.3 else ""))
    L += [""]
    L += best_policy_section(result)
    L += experiment_sections(result)
    L += action_section(result)
    L += ["## Plots", ""]
    for caption, path in figures:
        L += [f"**{caption}**", "", f"![{caption}]({path.relative_to(report_dir).as_posix()})", ""]
    L += ["## Reading the runs", "",
          "Each seed's run holds its learning curve (`metrics`, step = training step), its training episodes "
          "and its traced evaluation games; the final evaluations are the metrics with the suffix "
          + ("`@p0` (a world has no opponent setting)" if is_world(exp) else "`@p0.3` / `@p0.7`")
          + " at the last step:", "",
          "```",
          f"tracelab sql {result.arms[0].seeds[0].run_dir if result.arms[0].seeds else 'RUN'} \"SELECT name, value "
          "FROM metrics WHERE name LIKE 'eval/%@p%' ORDER BY name\"",
          "```", ""]
    path = report_dir / f"{exp.name}.md"
    path.write_text("\n".join(L))
    return path


def setting_rows(result: ExperimentResult) -> list[str]:
    """The report's rows on what is played and how games are counted: the war game's opponent and the method's
    counting, or a world's spec and its own declared outcomes."""
    if is_world(result.experiment):
        worlds = "; ".join(f"{ar.arm.label}: `{ar.arm.build_world().describe()}`" for ar in result.arms)
        return [f"| world | {worlds} |",
                "| counting | as the world declares (`[end] win` / `loss`, docs/worlds.md): wins, losses, draws "
                "(ended by neither), truncations (its step limit); the method's counting: a truncated game is a "
                "loss, so a world's method win rate is its win rate |"]
    return [f"| opponent | scripted blue: with probability p a move towards red's base, else a random action "
            f"(advanced: shoots first until out of ammo); training p = {TRAIN_P}, evaluation p = "
            f"{' and '.join(f'{p:g}' for p in eval_ps(result.experiment))} (the method's code: trained 0.7, "
            f"evaluated 0.3) |",
            f"| counting | tracelab's: wins, losses, draws, truncations (step limit) separately; the method's: "
            f"cut at {METHOD_CUT} steps, a cut game a loss, draws and wins by elimination non-wins |"]


def p_text(result: ExperimentResult, p: float) -> str:
    """An evaluation's opponent p in a table: '-' for a world, which has none."""
    return "-" if is_world(result.experiment) else f"{p:g}"


def against(result: ExperimentResult, p: float) -> str:
    return "" if is_world(result.experiment) else f" against p = {p:g}"


def p_label(result: ExperimentResult, p: float) -> str:
    return "final evaluation" if is_world(result.experiment) else f"p = {p:g}"


def action_section(result: ExperimentResult) -> list[str]:
    """Red's actions in each seed's last traced evaluation games: what the final greedy policy does
    (the war game's; a world's actions are in its runs' `steps`)."""
    if is_world(result.experiment):
        return []
    # the traces' steps.action is the spec's action id: the arms' spec's action names, by id
    names = max((action_names(arm_world(ar.arm).source) for ar in result.arms), key=len)
    ids = range(len(names))
    L = ["## What the final policies do", "",
         "Red's actions in the traced games of each seed's last evaluation during training (the run's "
         "`episodes` with `kind = 'eval'` at the last `train_step`, joined with `steps`), and how those games "
         "ended:", "", "| setting | seed | games | " + " | ".join(names) + " | outcomes |",
         "|---|---|---|" + "---|" * len(names) + "---|"]
    for ar in result.arms:
        for s in ar.seeds:
            acts = run_sql(s.run_dir, "SELECT s.action, count(*) AS n FROM steps s JOIN episodes e USING (episode) "
                                      "WHERE e.kind = 'eval' AND s.agent LIKE 'red-agent-%' AND e.train_step = "
                                      "(SELECT max(train_step) FROM episodes WHERE kind = 'eval') GROUP BY ALL")
            ends = run_sql(s.run_dir, "SELECT outcome, count(*) AS n, avg(steps) AS steps FROM episodes WHERE "
                                      "kind = 'eval' AND train_step = (SELECT max(train_step) FROM episodes WHERE "
                                      "kind = 'eval') GROUP BY ALL ORDER BY n DESC")
            total = sum(r["n"] for r in acts) or 1
            share = {r["action"]: r["n"] / total for r in acts}
            L.append(f"| {ar.arm.label} | {s.seed} | {sum(r['n'] for r in ends)} | "
                     + " | ".join(pct(share.get(i, 0.0)) for i in ids) + " | "
                     + ", ".join(f"{r['n']} {r['outcome']} ({r['steps']:.0f} steps)" for r in ends) + " |")
    return L + [""]


def goal_lines(result: ExperimentResult) -> list[str]:
    exp = result.experiment
    out = [f"Goal: {exp.goal}.", ""]
    for ar in result.arms:
        if is_world(exp) and ar.arm.published is None:  # the goal: every seed's final policy wins every game
            vals = [s.final[p].method_win_rate for s in ar.seeds for p in eval_ps(exp) if p in s.final]
            reached = sum(v >= 1.0 for v in vals)
            out.append(f"- {ar.arm.label}: {reached} of {len(vals)} seeds win every final game; win rate "
                       f"{spread_text(vals) if vals else '-'}.")
        if ar.arm.published is None or exp.name == "portability" or is_markov(exp):
            continue
        first = eval_ps(exp)[0]
        vals = [s.final[first].method_win_rate for s in ar.seeds if first in s.final]
        reached = sum(v >= ar.arm.published for v in vals)
        verdict = "**reached**" if vals and reached == len(vals) else "**not reached**"
        out.append(f"- {ar.arm.label}: {verdict}, {reached} of {len(vals)} seeds reach it with {result.budget.steps:,} "
                   f"steps: method's win rate{against(result, first)} {spread_text(vals)}; the method: "
                   f"{ar.arm.published_note}.")
        kept = [kept_or_final(s, first) for s in ar.seeds]
        if any(s.best for s in ar.seeds) and None not in kept:
            n_kept = sum(v >= ar.arm.published for v in kept)
            out.append(f"  The kept best policies (below): {n_kept} of {len(kept)} seeds reach it, {spread_text(kept)}.")
    if is_markov(exp):
        out += markov_lines(result)
    if exp.name == "portability":
        for ar in result.arms:
            for s in ar.seeds:
                for key, d in (ar.extra.get(s.seed) or {}).items():
                    out.append(f"- seed {s.seed}, {key}: {d['identical_games']}/{d['games']} games identical "
                               f"game by game with the same seeds; independent seeds: win-rate gap "
                               f"{d['win_gap_points']:+.1f} points (two-proportion p = {d['p_value']:.2f}), "
                               f"return gap {d['return_gap']:+.1f} ({num(100 * d['return_gap_relative'], '.1f')}%).")
    if exp.name == "reward-shaping":
        for before, after in zip(result.arms, result.arms[1:]):  # each change of the rewards, in order
            for sb, sa in zip(before.seeds, after.seeds):
                fb, fa = ({k: v for k, v in (ar.extra.get(s.seed) or {}).items() if k != "trace_run"}
                          for ar, s in ((before, sb), (after, sa)))
                same = "the same figures (the change did not move the greedy policy's games)" if fb == fa else \
                    "hidden steps/game {} -> {}, red shot/game {} -> {}, shoot share {} -> {}, " \
                    "method's win rate {} -> {}".format(
                        num(fb.get("hidden_steps_per_game")), num(fa.get("hidden_steps_per_game")),
                        num(fb.get("shot_per_game")), num(fa.get("shot_per_game")), pct(fb.get("shoot_share")),
                        pct(fa.get("shoot_share")), pct(sb.final[0.3].method_win_rate),
                        pct(sa.final[0.3].method_win_rate))
                out.append(f"- seed {sb.seed}, {before.arm.label} -> {after.arm.label}: {same}.")
            shares = [[(ar.extra.get(s.seed) or {}).get("shoot_share") for s in ar.seeds] for ar in (before, after)]
            if all(v is not None for v in shares[0] + shares[1]) and shares[0] and shares[1]:
                out.append(f"- {before.arm.label} -> {after.arm.label}, shoot share over seeds: "
                           f"{spread_text(shares[0])} -> {spread_text(shares[1])}.")
        out.append("- the queries' figures per seed are in the table below.")
    return out


def is_markov(exp: Any) -> bool:
    """The Markov vs non-Markov experiments (their arms are compared with the first, Markov, one)."""
    return exp.name.startswith("markov-vs-nonmarkov")


def best_policy_section(result: ExperimentResult) -> list[str]:
    """The policies each run kept at its best evaluation during training (RUN/policy-best), played on the
    same final-evaluation games as the final policies: fresh games, not the ones that selected them."""
    rows = [(ar, s) for ar in result.arms for s in ar.seeds if s.best]
    if not rows:
        return []
    L = ["## The kept best policies", "",
         "A run also keeps the policy of its best evaluation during training (`RUN/policy-best/`, chosen by "
         "the method's win rate against the evaluation's opponent over that evaluation's games; docs/training.md, \"The best "
         "policy\"). Here it plays the final evaluation's games (other games than those that chose it, the "
         "same ones the final policy played). Seeds whose final policy was their best have no row.", "",
         "| setting | seed | kept at step | opponent p | method win rate [95% CI] | final policy's | mean return |",
         "|---|---|---|---|---|---|---|"]
    for ar, s in rows:
        for p, r in s.best.items():
            lo, hi = wilson(r.method_wins, r.games)
            fin = s.final.get(p)
            L.append(f"| {ar.arm.label} | {s.seed} | {s.best_step:,} | {p_text(result, p)} | {pct(r.method_win_rate)} "
                     f"[{pct(lo)}-{pct(hi)}] | {pct(fin.method_win_rate) if fin else '-'} | {r.mean_return:.1f} |")
    L += ["", "Over seeds, each seed's kept policy (its final one where that was its best), method's counting:", ""]
    for ar in result.arms:
        for p in eval_ps(result.experiment):
            vals = [kept_or_final(s, p) for s in ar.seeds]
            if vals and None not in vals:
                L.append(f"- {ar.arm.label}{against(result, p)}: {spread_text(vals)}")
    return L + [""]


def kept_or_final(s: Any, p: float) -> float | None:
    """A seed's kept best policy's method win rate against p, or its final policy's when that was the best."""
    r = s.best.get(p) or s.final.get(p)
    return None if r is None else r.method_win_rate


def best_during_training(run_dir: Path) -> float | None:
    """The best evaluation of a seed's learning curve (the method's "best": the highest of its evaluations
    over training), method's counting against the evaluation opponent."""
    steps, vals = curves(run_dir, ("eval/method_win_rate",))["eval/method_win_rate"]
    return float(np.max(vals)) if len(vals) else None


def markov_lines(result: ExperimentResult) -> list[str]:
    """Each non-Markov arm against the Markov arm (the first), final policies and, the method's way, the best
    evaluation during training."""
    base, others = result.arms[0], result.arms[1:]
    out = []
    for ar in others:
        for what, pick in (("final", lambda s: s.final[0.3].method_win_rate),
                           ("best during training", lambda s: best_during_training(s.run_dir))):
            m = [v for v in map(pick, base.seeds) if v is not None]
            n = [v for v in map(pick, ar.seeds) if v is not None]
            if not (m and n):
                continue
            if min(n) > max(m):
                margin = "above Markov, outside"
            elif max(n) < min(m):
                margin = "below Markov, outside"
            else:
                margin = "not outside"
            out.append(f"- {what}: {ar.arm.label} {spread_text(n)} vs {base.arm.label} {spread_text(m)}: the "
                       f"margin is {margin} the seed spread (min of one vs max of the other). The method: best "
                       f"59% vs 85%.")
    return out


def experiment_sections(result: ExperimentResult) -> list[str]:
    exp = result.experiment
    L: list[str] = []
    if exp.name == "portability":
        L += ["## Portability: the same policy in both simulators", "",
              "Each seed's final policy (trained through war.toml, rules/gridworld/war.toml) plays the same "
              "number of games in the hand-written simulator (RefSim, game/refsim.py): once with the spec "
              "world's final-evaluation seeds (the "
              "games should be identical, length and return compared game by game, since the simulators agree "
              "step by step) and once with other seeds (an independent sample: the gap there is sampling "
              "noise, tested with a two-proportion z-test on the method's wins and a bootstrap 95% interval of "
              "the mean-return difference).", "",
              "| seed | opponent p | spec: method win rate | reference, same seeds | identical games | "
              "reference, other seeds | win-rate gap (points) | z-test p | return spec / reference | return gap "
              "[95% bootstrap CI] | relative |", "|---|---|---|---|---|---|---|---|---|---|---|"]
        for ar in result.arms:
            for s in ar.seeds:
                for key, d in (ar.extra.get(s.seed) or {}).items():
                    lo, hi = d["return_gap_ci"]
                    L.append(f"| {s.seed} | {key[2:]} | {pct(d['rules']['method_win_rate'])} | "
                             f"{pct(d['reference_same_seeds']['method_win_rate'])} | {d['identical_games']}/"
                             f"{d['games']} | {pct(d['reference_other_seeds']['method_win_rate'])} | "
                             f"{d['win_gap_points']:+.1f} | {d['p_value']:.2f} | {d['rules']['mean_return']:.1f} / "
                             f"{d['reference_other_seeds']['mean_return']:.1f} | {d['return_gap']:+.1f} "
                             f"[{lo:+.1f}, {hi:+.1f}] | {num(100 * d['return_gap_relative'], '.1f')}% |")
        L += [""]
    if exp.name == "reward-shaping":
        first = next((ar.extra.get(s.seed, {}).get("trace_run") for ar in result.arms for s in ar.seeds), None)
        L += ["## The case", "",
              "The method's point about explainability: its traces showed agents hiding behind mountains when "
              "the penalty for being shot was 400; halving it to 200 balanced the policy, and a penalty of 10 "
              "(not more) for shooting with no ammo kept agents shooting. Here, as one command:", "",
              "1. train on the advanced scenario with `got_shot = -400` (the rest of the rewards the method's);",
              "2. play 100 traced evaluation games of each seed's policy and run the saved queries on them:", "",
              "   ```",
              f"   tracelab sql {first or 'TRACES'} --query hid_behind_mountain",
              f"   tracelab sql {first or 'TRACES'} --query learner_events",
              f"   tracelab sql {first or 'TRACES'} --query actions_per_win --param learner=red-agent-%",
              f"   tracelab sql {first or 'TRACES'} --query steps_before_loss --param learner=red-agent-%",
              "   ```", "",
              "3. change the rewards the queries point to: `hid_behind_mountain` and `learner_events`' `shot` "
              "point to the shot penalty (-400 -> -200), `learner_events`' `invalid` and the shoot share to the "
              "no-ammo penalty (kept at -10, the method's value), and retrain with the same seeds;",
              "4. the same queries and the win rates, before and after (below);",
              "5. the other half of the method's remark, \"a penalty of 10 (not more) for shooting with no ammo\": "
              "the same shot penalty (-200) with the no-ammo penalty raised to -200, the unsafe-move penalty's "
              "size. The observation does not include red's own ammo (the method's observation), so a policy "
              "cannot tell a shot that hits from a shot with an empty gun before it fires.", ""]
        L += ["## The saved queries, before and after", "",
              "Each seed's final policy plays traced evaluation games (against p = 0.3) into its own run; the "
              "saved queries (`tracelab sql RUN --query NAME`) read them: `hid_behind_mountain` (timesteps red "
              "ended next to a mountain between it and a blue agent), `learner_events` (red shot, unsafe moves, "
              "invalid actions = shooting with no ammo), `actions_per_win`, `steps_before_loss` (red's last "
              "actions in lost games); `shoot share` = red's shooting actions among its actions (from `steps`). "
              "The traces are the spec world's (rules/gridworld/war.toml).",
              "", "| reward setting | seed | games | hidden steps / game | games with hiding | red shot / game | "
              "invalid (no ammo) / game | unsafe / game | shoot share | wins | actions per win | losses | last "
              "actions before a loss | method win rate (500-game eval) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for ar in result.arms:
            for s in ar.seeds:
                f = ar.extra.get(s.seed) or {}
                last = ", ".join(f"{k} {v}" for k, v in list(f.get("actions_before_loss", {}).items())[:3]) or "-"
                L.append(f"| {ar.arm.label} | {s.seed} | {f.get('games', 0)} | {num(f.get('hidden_steps_per_game'))} | "
                         f"{pct(f.get('games_with_hiding'))} | {num(f.get('shot_per_game'))} | "
                         f"{num(f.get('invalid_per_game'))} | {num(f.get('unsafe_per_game'))} | "
                         f"{pct(f.get('shoot_share'))} | {f.get('wins', 0)} | {num(f.get('actions_per_win'))} | "
                         f"{f.get('losses', 0)} | {last} | {pct(s.final[0.3].method_win_rate)} |")
        L += ["", "Rewards, the spec's `[reward]` params (`--env-arg`, docs/worlds.md): " + "; ".join(
            f"{ar.arm.label}: " + " ".join(f"`--env-arg {k}={v:g}`" for k, v in ar.arm.rewards.items())
            for ar in result.arms) + " (the rest war.toml's defaults, the method's).", ""]
    return L


def make_plots(result: ExperimentResult, fig_dir: Path) -> list[tuple[str, Path]]:
    small = result.quick
    n = result.budget.seeds
    arms = []
    for ar in result.arms:
        per_seed = []
        for s in ar.seeds:
            c = curves(s.run_dir, ("eval/method_win_rate", "eval/mean_return"))
            per_seed.append((s.seed, c))
        arms.append((ar, per_seed))

    def series(metric: str, with_published: bool) -> list[dict[str, Any]]:
        return [{"label": ar.arm.label, "published": ar.arm.published if with_published else None,
                 "seeds": [(seed, *c[metric]) for seed, c in per_seed]} for ar, per_seed in arms]

    ps = eval_ps(result.experiment)
    seeds_note = f"{n} seed{'s' if n != 1 else ''} per setting{against(result, ps[0])}, {result.budget.eval_games} " \
                 "games per point"
    out = [("Win rate (the method's counting) against training steps",
            plots.learning_curves(fig_dir / "win_rate.png", series("eval/method_win_rate", True),
                                  metric="eval/method_win_rate", ylabel="win rate, method's counting (%)",
                                  title=f"{result.experiment.title}: {seeds_note}", percent=True, small=small)),
           ("Mean return against training steps",
            plots.learning_curves(fig_dir / "mean_return.png", series("eval/mean_return", False),
                                  metric="eval/mean_return", ylabel="mean return (evaluation)",
                                  title=f"Mean return: {seeds_note}", percent=False, small=small))]
    by_p: dict[str, list] = {p_label(result, p): [] for p in ps}
    groups = []
    for ar in result.arms:
        for s in ar.seeds:
            groups.append(f"{textwrap.fill(ar.arm.label, 12)}\nseed {s.seed}" if len(result.arms) > 1
                          else f"seed {s.seed}")
            for p in ps:
                r: EvalFigures = s.final[p]
                lo, hi = wilson(r.method_wins, r.games)
                by_p[p_label(result, p)].append((r.method_win_rate, lo, hi))
    ref = result.arms[0].arm.published if len(result.arms) == 1 else None
    out.append(("Final win rate per seed" + ("" if is_world(result.experiment) else " against both opponent settings")
                + " (95% Wilson intervals)",
                plots.paired_bars(fig_dir / "final_win_rate.png", groups, by_p,
                                  ylabel="win rate, method's counting (%)", reference=ref, small=small,
                                  title=f"Final evaluation, {result.budget.eval_games} games each, {n} "
                                        f"seed{'s' if n != 1 else ''} per setting")))
    if result.experiment.name == "portability":
        groups, series_ = [], {"spec world": [], "reference, same seeds": [], "reference, other seeds": []}
        for ar in result.arms:
            for s in ar.seeds:
                for key, d in (ar.extra.get(s.seed) or {}).items():
                    groups.append(f"seed {s.seed}\np = {key[2:]}")
                    for name, k in (("spec world", "rules"), ("reference, same seeds", "reference_same_seeds"),
                                    ("reference, other seeds", "reference_other_seeds")):
                        r = d[k]
                        series_[name].append((r["method_win_rate"], *wilson(r["method_wins"], r["games"])))
        out.append(("Portability: the same policies in both simulators (95% Wilson intervals)",
                    plots.paired_bars(fig_dir / "portability.png", groups, series_, small=small,
                                      ylabel="win rate, method's counting (%)",
                                      title=f"Same policies, spec world vs hand-written simulator, "
                                            f"{result.budget.eval_games} games each, {n} seed{'s' if n != 1 else ''}")))
    return out


__all__ = ["write_report", "np", "p_suffix"]
