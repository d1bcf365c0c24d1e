"""Which env a command plays (`play --env`, `train --env`, `eval --env`): a registered id or a spec file,
with its keyword arguments (`--env-arg key=value`), as the user named it, recorded in runs and policies
(`to_json`), and made into an env. One class for the three commands: play reads a declared world's
spec from it (`declared`), train and eval make any env with Discrete actions (`make`)."""
from __future__ import annotations

import json
import os
import shlex
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

from tracelab.envs import make_env  # importing tracelab.envs registers the ids (declared/gridwar.py, toytext.py)
from tracelab.errors import UserError
from tracelab.world_extras import declared_id

DECLARED_ENTRY_POINT = "tracelab.envs.declared.gym_env:DeclaredEnv"


def _registry() -> Any:
    """gymnasium's registry with tracelab's ids in it (importing tracelab.envs registers them)."""
    return gym.registry


@dataclass(frozen=True)
class EnvSource:
    name: str                                  # a registered id (tracelab/FrozenLake-v1) or a spec path
    kwargs: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def given(cls, name: str, kwargs: dict[str, Any]) -> "EnvSource":
        """As the user names it: a spec file by its absolute path (a run or policy then names the same file
        from any folder), an id as it is."""
        if name not in _registry() and Path(name).is_file():
            name = str(Path(name).resolve())
        return cls(name, kwargs)

    @property
    def env_id(self) -> str | None:
        """The registered id whose entry is DeclaredEnv over its `spec` kwarg, or None for a spec file (and
        for an id whose registration maps its keyword arguments onto its spec's: world_extras.declared_id)."""
        return self.name if self.name in _registry() and declared_id(self.name, {}) is None else None

    @property
    def short_name(self) -> str:
        """For a run directory and messages: the id without its namespace, or the spec file's stem."""
        return self.name.split("/")[-1] if self.name in _registry() else Path(self.name).stem

    def declared(self) -> tuple[str, dict[str, Any]]:
        """The spec file of a declared world and the spec's [params] to load it with (an id's own fixed
        ones, map_name of FrozenLake8x8, then the user's); UserError when the source is not one."""
        mapped = declared_id(self.name, self.kwargs)
        if mapped is not None:
            return mapped
        if self.env_id is not None:
            entry = _registry()[self.env_id]
            kwargs = dict(entry.kwargs)
            if entry.entry_point != DECLARED_ENTRY_POINT or "spec" not in kwargs:
                raise UserError(f"--env {self.name}: a registered env, but not one declared in rules (play "
                                "--scenario plays the war game; --env takes a spec file or an id such as "
                                "tracelab/FrozenLake-v1)")
            return str(kwargs.pop("spec")), {**kwargs, **self.kwargs}
        if os.path.isfile(self.name):
            return self.name, dict(self.kwargs)
        declared = sorted(k for k, s in _registry().items() if s.entry_point == DECLARED_ENTRY_POINT)
        raise UserError(f"--env {self.name}: neither a spec file nor a registered id (the declared ids: "
                        f"{', '.join(declared)})")

    def with_args(self, **kwargs: Any) -> "EnvSource":
        """The same env with these keyword arguments set (an evaluation's: world_extras.evaluation_env)."""
        return EnvSource(self.name, {**self.kwargs, **kwargs})

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "kwargs": dict(self.kwargs)}

    def describe(self) -> str:
        """As the command line gives it: `tracelab/FrozenLake-v1 --env-arg is_slippery=false`."""
        return " ".join([shlex.quote(self.name),
                         *(f"--env-arg {shlex.quote(f'{k}={_toml_value(v)}')}" for k, v in self.kwargs.items())])

    def make(self) -> Any:
        """A new env (gym.make for a registered id, the war game's too: its TimeLimit and checks; make_env for a
        spec file)."""
        if self.name in _registry():
            return gym.make(self.name, **self.kwargs)
        if not Path(self.name).is_file():
            known = sorted(k for k in _registry() if k.startswith("tracelab/"))
            raise UserError(f"--env {self.name!r}: neither a registered env id ({', '.join(known)}, or "
                            f"gymnasium's) nor a spec file")
        return make_env(self.name, **self.kwargs)


def parse_env_args(texts: list[str]) -> dict[str, Any]:
    """`key=value` texts as keyword arguments; a value is read as a TOML value (false, 0.5, [1, 0, 0],
    "text") and otherwise kept as text (8x8)."""
    out: dict[str, Any] = {}
    for text in texts:
        key, eq, value = text.partition("=")
        key = key.strip()
        if not eq or not key.isidentifier():
            raise UserError(f"--env-arg {text!r}: expected key=value (write KEY=VALUE, e.g. is_slippery=false)")
        try:
            out[key] = tomllib.loads(f"v = {value.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = value.strip()
    return out


def _toml_value(value: Any) -> str:
    """A kwarg's value as --env-arg reads it back (TOML: true, 0.5, "8x8", ["SF", "HG"])."""
    return str(value).lower() if isinstance(value, bool) else json.dumps(value)


def env_source_from_json(d: Any, where: str) -> EnvSource:
    if not (isinstance(d, dict) and isinstance(d.get("name"), str) and isinstance(d.get("kwargs", {}), dict)):
        raise UserError(f"{where}: env: expected {{\"name\": str, \"kwargs\": {{...}}}}, got {str(d)[:80]}")
    return EnvSource(d["name"], dict(d.get("kwargs", {})))


def check_same_env(recorded: EnvSource, given: EnvSource, what: str) -> None:
    """One line naming both when `given` is not the env `what` (a policy, a checkpoint) was trained on."""
    if (recorded.name, recorded.kwargs) != (given.name, given.kwargs):
        raise UserError(f"{what} was trained on --env {recorded.describe()}, not {given.describe()}")
