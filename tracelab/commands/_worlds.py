"""The world a command's flags name: `--scenario` (a GridWar scenario: a built-in name or a .toml file) and
`--env SPEC_OR_ID` with its `--env-arg key=value`s. For train, eval, play and sweep, which all take them."""
from __future__ import annotations

import argparse
import dataclasses

from tracelab.envs.declared.env_source import EnvSource, parse_env_args
from tracelab.errors import UserError
from tracelab.game.scenario import Scenario, builtin_scenario, builtin_scenario_names, load_scenario


def load_scenario_arg(text: str, agents: int | None = None) -> Scenario:
    """A built-in scenario name or a .toml file, with `agents` per team if given."""
    sc = builtin_scenario(text) if text in builtin_scenario_names() else load_scenario(text)
    if agents is not None and agents != sc.agents_per_team:
        sc = dataclasses.replace(sc, agents_per_team=agents, red_starts=None, blue_starts=None)
    return sc


def env_source_of(args: argparse.Namespace) -> EnvSource:
    """--env and --env-arg as the EnvSource they name."""
    if args.env is None:
        raise UserError("--env-arg needs --env SPEC_OR_ID")
    return EnvSource.given(args.env, parse_env_args(args.env_arg))
