"""The world a command's flags name: `--env SPEC_OR_ID` with its `--env-arg key=value`s, for train, eval,
play and sweep, which all take them (the war game's `--scenario` and its flags:
tracelab/envs/declared/gridwar_scenarios.py)."""
from __future__ import annotations

import argparse

from tracelab.envs.declared.env_source import EnvSource, parse_env_args
from tracelab.errors import UserError


def env_source_of(args: argparse.Namespace) -> EnvSource:
    """--env and --env-arg as the EnvSource they name."""
    if args.env is None:
        raise UserError("--env-arg needs --env SPEC_OR_ID")
    return EnvSource.given(args.env, parse_env_args(args.env_arg))
