"""`tracelab experiment NAME --quick`: the command trains, evaluates against both opponent settings, writes
the figures into its runs and a report with plots (docs/experiments/). Real training, real plots: the
quick budgets are small, so the figures themselves are not asserted, only that they are there and
consistent."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("matplotlib")
from PIL import Image  # noqa: E402

from patience import PATIENCE, wait_until  # noqa: E402
from train_helpers import training  # noqa: E402

from tracelab.cli import main  # noqa: E402
from tracelab.store import open_run, run_info  # noqa: E402
from tracelab.train.experiments.runner import run_query  # noqa: E402
from tracelab.train.experiments.stats import spread, two_proportion_test, wilson  # noqa: E402


def run_quick(name: str, out: Path, capsys, *flags: str) -> str:
    assert main(["experiment", name, "--quick", "--out", str(out), *flags]) == 0
    return capsys.readouterr().out


def check_png(path: Path) -> None:
    assert path.exists(), path
    with Image.open(path) as im:
        assert im.format == "PNG"
        w, h = im.size
        assert w >= 400 and h >= 250
        low, high = im.convert("L").getextrema()
        assert high - low > 100  # something was drawn, not a blank canvas


def final_metrics(run: Path) -> dict[str, float]:
    con = open_run(run)
    try:
        rows = con.execute("SELECT name, value FROM metrics WHERE name LIKE 'eval/%@p%'").fetchall()
    finally:
        con.close()
    return dict(rows)


def test_1v1_base_quick(tmp_path, capsys):
    out = tmp_path / "exp"
    printed = run_quick("1v1-base", out, capsys, "--kernel", "counting")
    assert run_info(out / "1v1-base-seed0").meta["config"]["kernel"] == "counting"
    report = out / "1v1-base.md"
    assert f"report: {report}" in printed
    text = report.read_text()
    for section in ("# 1v1 base scenario", "| command | `tracelab experiment 1v1-base --quick", "| commit |",
                    "| machine | ", "cores", "| wall time |", "| opponent |", "training p = 0.7",
                    "evaluation p = 0.3 and 0.7", "## Result", "## Final evaluations, per seed", "## Plots"):
        assert section in text, section
    assert re.search(r"\| commit \| `[0-9a-f]{40}", text)
    assert "the method: 97.6% after 760K steps" in text
    # one row per opponent setting, counts that add up to the games
    rows = [r for r in text.splitlines() if r.startswith(("| 1v1 base | 0 | 0.3 |", "| 1v1 base | 0 | 0.7 |"))]
    assert len(rows) == 2
    for r in rows:
        cells = [c.strip() for c in r.strip("|").split("|")]
        games, wins, losses, draws, truncated = map(int, cells[3:8])
        assert games == 40 and wins + losses + draws + truncated == games
    for png in ("win_rate.png", "mean_return.png", "final_win_rate.png"):
        check_png(out / "1v1-base" / png)
        assert f"(1v1-base/{png})" in text
    # the run holds the final evaluations against both settings, and they match the report's JSON
    m = final_metrics(out / "1v1-base-seed0")
    summary = json.loads((out / "1v1-base.json").read_text())
    final = summary["arms"][0]["seeds"][0]["final"]
    for p in ("0.3", "0.7"):
        assert m[f"eval/games@p{p}"] == 40
        assert m[f"eval/method_win_rate@p{p}"] == pytest.approx(final[f"@p{p}"]["method_win_rate"])
    # the report can be written again from the runs alone
    again = tmp_path / "again"
    assert main(["experiment", "1v1-base", "--report-only", "--out", str(out), "--report-dir", str(again)]) == 0
    assert (again / "1v1-base.md").read_text().split("## Result")[1] == text.split("## Result")[1]
    # an existing run is not overwritten
    assert main(["experiment", "1v1-base", "--quick", "--out", str(out)]) == 1
    assert "already exists" in capsys.readouterr().err


SPEC_TRAINER = "trains the war game through its spec (rules/gridworld/war*.toml, EnvTrainer)"


@pytest.mark.parametrize("name", ["1v1-base", "5v5-base", "portability", "markov-vs-nonmarkov",
                                  "markov-vs-nonmarkov-every-step", "reward-shaping"])
def test_every_gridwar_experiment_trains_through_its_spec(name):
    from tracelab.train.experiments import run
    from tracelab.train.experiments.definitions import EXPERIMENTS
    assert run.trainer_note(EXPERIMENTS[name]) == SPEC_TRAINER


def action_shares(text: str, label: str) -> list[float]:
    """The action shares of a report's "What the final policies do" row of `label`, seed 0."""
    rows = text.split("## What the final policies do")[1].splitlines()
    row = next(r for r in rows if r.startswith(f"| {label} | 0 |"))
    return [float(c.strip().rstrip("%")) for c in row.strip("|").split("|")[3:-1]]


def test_portability_plays_the_spec_policy_in_refsim_game_by_game(tmp_path, capsys):
    """portability trains through GridWar's spec and plays the final spec policy in RefSim with the spec
    world's evaluation seeds: the same games, game by game, and with other seeds; no RuleSim on the way."""
    out = tmp_path / "exp"
    run_quick("portability", out, capsys, "--steps", "300", "--eval-games", "10")
    text = (out / "portability.md").read_text()
    assert f"| trainer | {SPEC_TRAINER} |" in text
    assert "## Portability: the same policy in both simulators" in text
    policy = json.loads((out / "1v1-base-seed0" / "policy" / "policy.json").read_text())
    assert policy["format"] == "tracelab-dqn-env-policy/1" and policy["env"]["name"] == "tracelab/GridWar-base-v0"
    summary = json.loads((out / "portability.json").read_text())
    extra = summary["arms"][0]["seeds"][0]["extra"]
    for key in ("@p0.3", "@p0.7"):
        d = extra[key]
        # the simulators agree step by step: the same seeds give the same games, game by game
        assert d["identical_games"] == d["games"] == 10
        for field in ("method_wins", "losses", "draws", "truncated", "mean_return"):
            assert d["reference_same_seeds"][field] == d["rules"][field], field
        assert d["rules"]["games"] == d["reference_other_seeds"]["games"] == 10
        assert 0.0 <= d["p_value"] <= 1.0
        assert f"| 0 | {key[2:]} |" in text
    # the spec's five actions (its ids 0-4, "nothing" the last), each game's every action counted
    assert sum(action_shares(text, "1v1 base")) == pytest.approx(100.0, abs=0.3)
    assert "| setting | seed | games | up | down | left | right | nothing | outcomes |" in text
    for png in ("win_rate.png", "mean_return.png", "final_win_rate.png", "portability.png"):
        check_png(out / "portability" / png)


def test_a_spec_policy_plays_the_same_games_in_refsim(tmp_path):
    """refsim_games: an untrained spec policy (its network as initialised, seeded) in RefSim and in the spec's
    vector env with the same seed: the same returns and lengths in the same order, for both opponents."""
    import torch

    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.game.scenario import builtin_scenario
    from tracelab.train.env_policy import EnvPolicy, evaluate_env
    from tracelab.train.env_source import probe_env
    from tracelab.train.dqn import make_q_network
    from tracelab.train.experiments.refsim_games import refsim_games
    from tracelab.train.qnet import NetSpec, TorchQ

    source = EnvSource("tracelab/GridWar-base-v0", {})
    encoder, n_actions, _ = probe_env(source)
    net = make_q_network(NetSpec(encoder.size, (16,), n_actions), torch.Generator().manual_seed(3))
    policy = EnvPolicy(TorchQ(net), encoder)
    for p in (0.3, 0.7):
        spec = evaluate_env(policy, EnvSource(source.name, {"p_toward": p}), 12, 5, 4)
        ref = refsim_games(policy, builtin_scenario("base"), 12, 5, 4, p)
        assert (ref.returns, ref.steps, ref.wins, ref.losses, ref.draws, ref.truncated) == \
            (spec.returns, spec.steps, spec.wins, spec.losses, spec.draws, spec.truncated)
        assert len(set(spec.returns)) > 1  # different games, not one repeated


def test_reward_shaping_traces_spec_games_with_the_specs_reward_params(tmp_path, capsys):
    """reward-shaping trains each arm on GridWar's advanced spec with its rewards as the spec's params, and
    its saved queries read traced games of the spec world (a run of their own per seed)."""
    out = tmp_path / "exp"
    run_quick("reward-shaping", out, capsys, "--steps", "200", "--eval-games", "8")
    text = (out / "reward-shaping.md").read_text()
    assert f"| trainer | {SPEC_TRAINER} |" in text
    assert "`--env-arg got_shot=-400`" in text
    summary = json.loads((out / "reward-shaping.json").read_text())
    for arm, kwargs in zip(summary["arms"], ({"got_shot": -400.0}, {}, {"invalid": -200.0})):
        seed = arm["seeds"][0]
        assert run_info(Path(seed["run"])).meta["config"]["env"] == {"name": "tracelab/GridWar-advanced-v0",
                                                                      "kwargs": kwargs}
        figures = seed["extra"]
        traces = run_info(Path(figures["trace_run"])).meta
        assert traces["config"]["env"] == {"name": "tracelab/GridWar-advanced-v0",
                                           "kwargs": {**kwargs, "p_toward": 0.3}}
        con = open_run(Path(figures["trace_run"]))
        try:
            episodes, shots = con.execute("SELECT count(*), sum(steps) FROM episodes").fetchone()
            shot, invalid = con.execute(
                "SELECT count(*) FILTER (label = 'gotShot'), count(*) FILTER (label = 'invalid') FROM changes "
                "WHERE node LIKE 'red-agent-%' AND new_lower = 1 AND new_upper = 1").fetchone()
        finally:
            con.close()
        assert episodes == figures["games"] == 6
        assert figures["shot_per_game"] == pytest.approx(shot / 6)
        assert figures["invalid_per_game"] == pytest.approx(invalid / 6)
        hid = run_query(Path(figures["trace_run"]), "hid_behind_mountain")  # the spec's cells, c{row}_{col}
        assert len(hid) == 6 and figures["hidden_steps_per_game"] == pytest.approx(
            sum(r["hidden_steps"] for r in hid) / 6)
        assert figures["wins"] + figures["losses"] <= 6


def test_markov_vs_nonmarkov_quick_compares_observations_with_one_shared_network(tmp_path, capsys):
    out = tmp_path / "exp"
    run_quick("markov-vs-nonmarkov", out, capsys)
    text = (out / "markov-vs-nonmarkov.md").read_text()
    policies = {run: json.loads((out / run / "policy" / "policy.json").read_text())
                for run in ("markov-seed0", "non-markov-seed0")}
    # both arms train one network on the spec's nonmarkov game; they differ only in the observation: the
    # non-Markov one also sees the previous step (stack_previous), so twice the numbers an agent
    markov, non_markov = (policies[r] for r in ("markov-seed0", "non-markov-seed0"))
    assert markov["env"]["name"] == non_markov["env"]["name"] == "tracelab/GridWar-nonmarkov-v0"
    agents = 2  # each row ends with the agent's one-hot index among the team's two
    assert non_markov["network"]["inputs"] - agents == 2 * (markov["network"]["inputs"] - agents)
    assert {k: v for k, v in markov["network"].items() if k not in ("inputs", "torch")} == \
        {k: v for k, v in non_markov["network"].items() if k not in ("inputs", "torch")}
    assert "non-Markov: reward scale 0.01, explore scripted 0.5" in text
    for what in ("final", "best during training"):
        assert re.search(rf"- {what}: non-Markov mean [0-9.]+%.* vs Markov mean", text), what


def test_statistics():
    lo, hi = wilson(488, 500)
    assert lo < 0.976 < hi and 0.95 < lo and hi < 0.99
    assert wilson(0, 40)[0] == 0.0
    for n in (40, 200, 500, 1000):  # the interval holds the proportion at its ends too (error bars >= 0)
        assert wilson(n, n)[1] == 1.0 and wilson(0, n)[0] == 0.0
    z, p = two_proportion_test(488, 500, 440, 500)
    assert z > 0 and p < 1e-6
    assert two_proportion_test(250, 500, 250, 500)[1] == pytest.approx(1.0)
    s = spread([0.9, 0.95, 1.0])
    assert s["min"] == 0.9 and s["max"] == 1.0 and s["ci_low"] < 0.95 < s["ci_high"]


def test_bad_arguments(capsys):
    with pytest.raises(SystemExit) as exit_:  # a usage error: argparse's message, exit 2
        main(["experiment", "1v1-base", "--seeds", "0"])
    assert exit_.value.code == 2
    assert "argument --seeds: must be at least 1, got 0" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["experiment", "no-such"])


def _children(pid: int) -> set[int]:
    try:
        return {int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()}
    except FileNotFoundError:
        return set()


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="reads child processes from /proc")
def test_sigterm_to_a_parallel_experiment_stops_its_workers(tmp_path):
    """A scheduler's SIGTERM to `tracelab experiment --jobs 2` ends the workers' trainings too (they used to
    train on as orphans), and each run it began is closed as interrupted."""
    out = tmp_path / "exp"
    proc = subprocess.Popen([sys.executable, "-m", "tracelab", "experiment", "1v1-base", "--quick", "--seeds", "1",
                             "--steps", "50000000", "--jobs", "2", "--kernel", "counting", "--out", str(out)],
                            stderr=subprocess.PIPE, text=True)
    runs = [out / "1v1-base-seed0", out / "1v1-base-the-method-s-reward-scale-seed0"]  # its two arms
    workers: set[int] = set()
    try:
        _terminate_when_training(proc, runs, workers)
    finally:  # a failing check leaves nothing running
        for pid in [proc.pid, *workers]:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        proc.wait()
    assert [run_info(r).status for r in runs] == ["interrupted", "interrupted"]


def _terminate_when_training(proc, runs: list[Path], workers: set[int]) -> None:
    def started() -> bool:
        workers.update(_children(proc.pid))
        return training(proc, runs)
    wait_until(started, f"both arms of {runs[0].parent} training", poll=0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=PATIENCE)
    assert proc.returncode == 130, err
    assert "no report written" in err.strip().splitlines()[-1]
    wait_until(lambda: not any(_alive(p) for p in workers), "the workers gone after the pool's end", poll=0.2)
    assert workers


def test_an_experiment_on_a_world_of_its_own_counts_its_declared_outcomes(tmp_path, capsys):
    """trap-corridor trains train --env's trainer on a repo spec (rules/examples/trap_corridor.toml) with a
    param per arm: its final evaluations are counted as the world declares ([end] win / loss), written into
    the runs, the report and its JSON, and the report is written again from them (issue 38, item 3)."""
    out = tmp_path / "exp"
    run_quick("trap-corridor", out, capsys)
    text = (out / "trap-corridor.md").read_text()
    assert "| world | door reward 1: `" in text and "door_reward=0.2" in text and "| opponent |" not in text
    summary = json.loads((out / "trap-corridor.json").read_text())
    for arm, slug, reward in ((0, "door-reward-1-seed0", 1.0), (1, "door-reward-0-2-seed0", 0.2)):
        run = out / slug
        assert run_info(run).meta["config"]["env"]["kwargs"] == {"door_reward": reward}
        m = final_metrics(run)
        assert m["eval/games@p0"] == 12
        assert m["eval/wins@p0"] + m["eval/losses@p0"] + m["eval/draws@p0"] + m["eval/truncated@p0"] == 12
        final = summary["arms"][arm]["seeds"][0]["final"]["@p0"]
        assert final["wins"] == m["eval/wins@p0"] and final["method_win_rate"] == m["eval/win_rate@p0"]
        row = [r for r in text.splitlines() if r.startswith(f"| {summary['arms'][arm]['label']} | 0 | - |")]
        cells = [c.strip() for c in row[0].strip("|").split("|")]
        assert list(map(int, cells[3:8])) == [12, final["wins"], final["losses"], final["draws"], final["truncated"]]
        # the world's returns: a loss in the trap is -1, a win at the door the arm's reward
        assert m["eval/mean_return@p0"] == pytest.approx((final["wins"] * reward - final["losses"]) / 12)
    for png in ("win_rate.png", "mean_return.png", "final_win_rate.png"):
        check_png(out / "trap-corridor" / png)
    again = tmp_path / "again"
    assert main(["experiment", "trap-corridor", "--report-only", "--out", str(out), "--report-dir", str(again)]) == 0
    assert (again / "trap-corridor.md").read_text().split("## Result")[1] == text.split("## Result")[1]
