"""GridWar's scenarios where the commands meet them, part of its registration (gridwar.py): the flags that
name one (`--scenario NAME_OR_FILE`, `--agents`, `--opponent-p`) as the EnvSource of the spec that plays it,
and the files of RuleSim's trainer (every GridWar policy before GridWar trained through its spec, issue 38):
its policies converted at load into the EnvPolicy of their scenario's spec, whose observation is RuleSim's
(tests/test_gridwar_spec.py), so that they play as they played RuleSim. A team's policy of that format read
each agent's view with its own blocks first, which no EnvPolicy reads: refused in one line giving the
command that trains it again. play, eval, train, sweep and the experiments call these and have no branch of
their own for the game."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import shlex
import tomllib
from pathlib import Path
from collections.abc import Mapping
from typing import Any

from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.gridwar import (
    GRIDWAR_SPEC_IDS,
    WAR_ADVANCED_2V2,
    WAR_NONMARKOV,
    WAR_SPEC,
    scenario_env,
)
from tracelab.errors import UserError
from tracelab.game.scenario import ACTION_NAMES, Scenario, builtin_scenario, builtin_scenario_names, load_scenario
from tracelab.game.scenario import scenario_from_dict
from tracelab.train.env_policy import (
    NETWORK_SCHEMA,
    POLICY_JSON,
    EnvPolicy,
    TeamPolicy,
    load_env_policy,
    numpy_network,
    policy_dir,
    policy_format,
    read_policy_json,
    read_policy_networks,
    spec_net,
)
from tracelab.store.meta import current_meta
from tracelab.train.budget import reward_scale_note, too_short_hint
from tracelab.train.env_source import TeamEncoder, probe_env
from tracelab.validation import Const, IntRange, ListOf, MapOf, OptionalKey, check_file

DEFAULT_SCENARIO = "base"  # what play and train play without --scenario
# train's flags for the scenario (TrainConfig's fields once: train.config.RETIRED_FIELDS), by their args names
SCENARIO_FLAGS = ("scenario", "agents", "non_markov", "opponent_p", "eval_p")
METHOD_EVAL_P = 0.3  # the method's evaluation: the opponent's p that eval plays by default
_SPEC_FILES = {str(WAR_SPEC), str(WAR_NONMARKOV), str(WAR_ADVANCED_2V2)}


def load_scenario_arg(text: str, agents: int | None = None) -> Scenario:
    """`--scenario`: a built-in scenario name or a .toml file, with `agents` per team if given."""
    sc = builtin_scenario(text) if text in builtin_scenario_names() else load_scenario(text)
    if agents is not None and agents != sc.agents_per_team:
        sc = dataclasses.replace(sc, agents_per_team=agents, red_starts=None, blue_starts=None)
    return sc


def check_opponent_p(p: float | None, flag: str = "--opponent-p") -> None:
    if p is not None and not 0.0 <= p <= 1.0:
        raise UserError(f"{flag} must be in [0, 1], got {p}")


def has_opponent_p(source: EnvSource) -> bool:
    """Whether `source` is one of the game's ids or spec files: a scripted opponent --opponent-p sets."""
    return source.name in GRIDWAR_SPEC_IDS or source.name in _SPEC_FILES


def with_opponent_p(source: EnvSource, p: float | None) -> EnvSource:
    """`source` with its opponent at --opponent-p `p` (unchanged for None); refused in one line for a world
    with no scripted opponent."""
    if p is None:
        return source
    check_opponent_p(p)
    if not has_opponent_p(source):
        raise UserError(f"--opponent-p is GridWar's scripted opponent's; {source.describe()} has none")
    return source.with_args(p_toward=p)


def refuse_scenario_flags(args: Any, why: str, flags: tuple[str, ...] = ("scenario", "agents", "opponent_p")) -> None:
    """A UserError naming the scenario's flags (`flags`: their args names) given where they do not apply,
    and `why`."""
    given = [f"--{f.replace('_', '-')}" for f in flags if getattr(args, f, None) is not None]
    refused = scenario_settings_given(given, why)
    if refused:
        raise UserError(refused)


def scenario_settings_given(names: list[str], why: str) -> str | None:
    """The line refusing the scenario's settings `names` (SCENARIO_FLAGS, as flags or field names) where a
    world of its own plays or trains, or None when there are none."""
    if not names:
        return None
    return f"{', '.join(names)} describe{'s' * (len(names) == 1)} GridWar; {why}"


def scenario_world(args: Any, trained: dict[str, Any] | None = None,
                   p: float | None = None) -> tuple[Scenario, EnvSource]:
    """play's and eval's `--scenario NAME_OR_FILE` (base without it; the scenario of `trained`, a policy of
    RuleSim's trainer's policy.json, unless --scenario or play's --agents says), its --opponent-p (`p`
    without it): the scenario and the GridWar id and params that play it (scenario_env, with `trained`'s
    observation of the previous step); a UserError naming what no spec plays."""
    agents = getattr(args, "agents", None)
    if trained is not None and args.scenario is None and agents is None:
        scenario = rulesim_scenario(trained)
    else:
        scenario = load_scenario_arg(args.scenario or DEFAULT_SCENARIO, agents)
    p = p if args.opponent_p is None else args.opponent_p
    check_opponent_p(p)
    try:
        return scenario, EnvSource(*scenario_env(scenario, p, trained is not None and
                                                 trained["observation"]["stack_previous"]))
    except UserError as e:
        if trained is None:
            raise
        raise UserError(f"{args.policy} (a GridWar policy of RuleSim's trainer) cannot be played: {e}") from None


@dataclass(frozen=True)
class ScenarioTraining:
    """`train --scenario`: the scenario as the spec id and params it trains on (its flags are the spec's
    params: --agents agents_per_team, --non-markov stack_previous, --opponent-p p_toward) and the env its
    evaluations play (p_toward at --eval-p); the run names the scenario and keeps its TOML (run_config)."""
    scenario: Scenario
    source: EnvSource       # the env it trains on
    eval_source: EnvSource  # the one its evaluations play

    @classmethod
    def of(cls, scenario: Scenario, opponent_p: float | None = None, eval_p: float | None = None,
           non_markov: bool = False) -> ScenarioTraining:
        """`scenario` (an experiment's arm: its own rewards) against the opponent at `opponent_p` (the spec's
        default: None), evaluated at `eval_p` (the method's: None); a UserError naming what its spec cannot
        play (scenario_env)."""
        check_opponent_p(opponent_p)
        check_opponent_p(eval_p, "--eval-p")
        source = EnvSource(*scenario_env(scenario, opponent_p, non_markov))
        return cls(scenario, source, source.with_args(p_toward=METHOD_EVAL_P if eval_p is None else eval_p))

    @classmethod
    def given(cls, flags: Mapping[str, Any]) -> ScenarioTraining:
        """train's (or a sweep's) scenario flags, by their SCENARIO_FLAGS names: base without --scenario."""
        return cls.of(load_scenario_arg(flags.get("scenario") or DEFAULT_SCENARIO, flags.get("agents")),
                      flags.get("opponent_p"), flags.get("eval_p"), bool(flags.get("non_markov")))

    @property
    def name(self) -> str:
        return self.scenario.name

    def run_config(self) -> dict[str, Any]:
        """What the run's config keeps of it beside the env it trained on: the scenario's TOML (show and
        compare list its fields) and the evaluations' env."""
        return {"scenario_toml": self.scenario.to_toml(), "eval_env": self.eval_source.to_json()}

    def describe(self) -> str:
        return f"{self.name} (--env {self.source.describe()}; its evaluations: --env {self.eval_source.describe()})"

    def reward_note(self, reward_scale: float) -> str | None:
        """The note on a reward scale far from the scenario's rewards (budget.reward_scale_note)."""
        rewards = dataclasses.asdict(self.scenario.rewards).values()
        return reward_scale_note(max(abs(v) for v in rewards), reward_scale)

    def hint(self, steps: int, wins: int) -> str | None:
        """The hint for a training too short to win (budget.too_short_hint)."""
        return too_short_hint(steps, wins, self.scenario.agents_per_team)


def resumed_scenario(run: str, recorded: EnvSource, scenario_given: str | None) -> ScenarioTraining | None:
    """`train --resume RUN` of a `train --scenario` run (one of the game's ids, its meta's config holding the
    scenario's TOML): that scenario on the checkpoint's env `recorded`, evaluated at its config's eval_env's
    p_toward (a run of an earlier tracelab: its config's eval_p, once a TrainConfig field); None for any other
    run. `--scenario` given again must name the same scenario."""
    config = _run_config(Path(run))
    text = config.get("scenario_toml")
    if recorded.name not in GRIDWAR_SPEC_IDS or not isinstance(text, str):
        return None
    scenario = scenario_of_toml(text, f"{run}/meta.json: key 'config.scenario_toml'")
    if scenario_given is not None and load_scenario_arg(scenario_given).to_toml() != scenario.to_toml():
        raise UserError(f"--scenario {scenario_given}: {run} trained scenario {scenario.name!r}")
    evaluated = config.get("eval_env")
    p = evaluated.get("kwargs", {}).get("p_toward") if isinstance(evaluated, dict) else config.get("eval_p")
    if p is not None and (isinstance(p, bool) or not isinstance(p, (int, float))):
        raise UserError(f"{run}/meta.json: config: the evaluations' p_toward must be a number, got {p!r}")
    check_opponent_p(p, f"{run}/meta.json: config: the evaluations' p_toward")
    return ScenarioTraining(scenario, recorded, recorded.with_args(p_toward=METHOD_EVAL_P if p is None else p))


def _run_config(run: Path) -> dict[str, Any]:
    """The config in `run`'s meta.json ({} when it is not a run: the checkpoint's loader says what it is)."""
    try:
        config = current_meta(run).get("config", {})
    except (OSError, ValueError, AttributeError):
        return {}
    return config if isinstance(config, dict) else {}


# ---- RuleSim's trainer's files ------------------------------------------------------------------------

RULESIM_FORMAT = "tracelab-dqn-policy/1"  # RuleSim's trainer's policies: read and converted, never written
RULESIM_SPEC_SCHEMA = {
    "format": Const(RULESIM_FORMAT),
    "scenario": {"name": str, "toml": str},
    "observation": {"stack_previous": bool},
    "network": NETWORK_SCHEMA,
    "networks": MapOf(ListOf(IntRange(0), min_len=1), min_len=1),
    "mask": OptionalKey(bool),
}


def read_rulesim_spec(path: str | Path) -> dict[str, Any]:
    """policy.json of a policy of RuleSim's trainer, checked against its schema, and refused in one line
    unless it converts exactly into an EnvPolicy: one agent, one network (a team's network read each
    agent's view with its own blocks first, which tracelab's team policies do not: the line gives the
    command that trains the scenario again, on its spec)."""
    f, raw = read_policy_json(path)
    spec = check_file(raw, RULESIM_SPEC_SCHEMA, f)
    scenario = rulesim_scenario(spec, f)
    if scenario.agents_per_team != 1:
        named = shlex.quote(scenario.name) if scenario.name in builtin_scenario_names() else "SCENARIO_FILE"
        retrain = f"tracelab train --scenario {named} --agents {scenario.agents_per_team}" + \
            (" --non-markov" if spec["observation"]["stack_previous"] else "")
        raise ValueError(f"{f.parent}: a policy of GridWar's earlier trainer (RuleSim's format) for "
                         f"{scenario.agents_per_team} agents a team, each reading the team with its own blocks first, which today's team policies "
                         f"(one network, each agent's index as input) cannot play as trained; train it again "
                         f"on its spec: {retrain}")
    if list(spec["networks"].values()) != [[0]]:
        raise ValueError(f"{f}: key 'networks': expected one network, playing agent 0 (a one-agent scenario)")
    return spec


def rulesim_scenario(spec: dict[str, Any], where: str | Path = POLICY_JSON) -> Scenario:
    """The scenario a RuleSim-format policy.json (read_rulesim_spec) was trained on."""
    return scenario_of_toml(spec["scenario"]["toml"], f"{where}: key 'scenario.toml'")


def scenario_of_toml(text: str, where: str) -> Scenario:
    """A scenario's TOML as a file (a policy's, a run's config) holds it; a ValueError naming `where`."""
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{where}: not TOML: {e}") from None
    return scenario_from_dict(table, source=where)


def _load_rulesim_policy(path: str | Path, spec: dict[str, Any], given: EnvSource,
                         world_spec: Any = None) -> EnvPolicy:
    """A policy of RuleSim's trainer (one agent) as the EnvPolicy that plays it on the world `given` names,
    a spec whose observation and actions are its scenario's. RuleSim gave one agent the team's view, as the
    spec does, so its network reads the spec's observation as it is: the same games (tests/test_play.py).
    A world of another shape is refused in one line naming both."""
    trained_on = rulesim_scenario(spec)
    net = spec_net(spec)
    (state,) = read_policy_networks(path, spec).values()  # sized and checked before the world is built
    encoder, n_actions, world = probe_env(given, world_spec)
    agents = encoder.n_agents if isinstance(encoder, TeamEncoder) else 1
    names = [ACTION_NAMES[a] for a in trained_on.action_ids]
    world_names = names if world is None else list(world.action_names)
    if (agents, n_actions, encoder.size, world_names) != (1, net.actions, net.inputs, names):
        raise ValueError(f"{policy_dir(path)}: trained on GridWar's {trained_on.name!r} (1 agents, "
                         f"{net.actions} actions, {net.inputs} observations); {given.describe()} has {agents} "
                         f"agents, {n_actions} actions, {encoder.size} observations"
                         + ("" if len(world_names) != len(names) or world_names == names else
                            f" (actions {', '.join(world_names)}, not {', '.join(names)})"))
    return EnvPolicy(numpy_network(net, state), encoder, spec.get("mask", False))


def load_trained(path: str | Path, given: EnvSource, spec: Any = None) -> EnvPolicy | TeamPolicy:
    """A policy of either format, to play on the world `given` names: one of train (load_env_policy: the same
    env it was trained on), or one of RuleSim's trainer converted. `spec`: `given`'s WorldSpec if loaded
    already."""
    if policy_format(path) == RULESIM_FORMAT:
        return _load_rulesim_policy(path, read_rulesim_spec(path), given, spec)
    return load_env_policy(path, given, spec)[0]
