"""`DeclaredEnv`: a world declared by a spec (docs/worlds.md) as a gymnasium Env.

The spaces come from the spec: actions Discrete(number of actions); the observation Discrete (one index,
or several as one number, first part most significant: numpy's ravel_multi_index), MultiDiscrete (the
parts' indices), Box (the parts' numbers, float32, in order) or Dict (a space per part). `info` holds
`action_mask` (int8, 1 = allowed) when the spec declares a mask, and `t` (steps into the episode).
`trace_writer`: a TraceWriter the env records its games into (recording.py); env.close() closes it, unless
`trace_episode_ids` is given: the run is then another's (a training's, recording its evaluation games), the
games take their episode ids from it and begin with the info `trace_info()` sets."""
from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from tracelab.envs.declared.history import ObservationHistory, stacked_space
from tracelab.envs.declared.render import DeclaredPainter
from tracelab.envs.declared.spec import WorldSpec, load_spec
from tracelab.envs.declared.world import DeclaredWorld

if TYPE_CHECKING:
    from tracelab.envs.declared.recording import DeclaredRecorder
    from tracelab.store.agent_rows import PolicyOutput
    from tracelab.store.writer import TraceWriter

RENDER_MODES = ["ansi", "rgb_array"]


class DeclaredEnv(gym.Env[Any, np.int64]):
    metadata = {"render_modes": RENDER_MODES, "render_fps": 4}

    def __init__(self, spec: WorldSpec | str | os.PathLike[str], *, render_mode: str | None = None,
                 kernel: str = "auto", trace_writer: TraceWriter | None = None,
                 trace_episode_ids: Callable[[], int] | None = None, trace_agent_rows: bool = True,
                 **params: Any) -> None:
        self.world_spec = spec if isinstance(spec, WorldSpec) else load_spec(spec, **params)
        if len(self.world_spec.agents) != 1:
            raise ValueError(f"{self.world_spec.path}: a gymnasium Env plays one agent; this spec declares "
                             f"{len(self.world_spec.agents)} (tracelab.envs.declared.parallel_env.DeclaredParallelEnv "
                             "plays them all)")
        self._painter = painter_for(self.world_spec, render_mode)
        self.render_mode = render_mode
        self.world = DeclaredWorld(self.world_spec, kernel=kernel, trace=trace_writer is not None)
        self._recorder: DeclaredRecorder | None = None
        if trace_writer is not None:
            # deferred: the store's modules (DuckDB) only load for a traced env
            from tracelab.envs.declared.recording import DeclaredRecorder
            self._recorder = DeclaredRecorder(self.world, trace_writer, trace_episode_ids, trace_agent_rows)
        self.metadata = {**self.metadata, "render_fps": self.world_spec.render_fps}
        self._n_actions = len(self.world_spec.action_names)
        self.action_space = spaces.Discrete(self._n_actions)
        self.observation_space = observation_space(self.world_spec)
        self._history = ObservationHistory(self.world_spec.previous)
        self._running = False
        self._last_action: int | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        if self._recorder is not None:
            self._recorder.before_reset()
        self.world.reset(self.np_random)
        if self._recorder is not None:
            self._recorder.begin(seed)
        self._running = True
        self._last_action = None
        return self._history.start(self._observe()), self._info()

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if not self._running:
            raise RuntimeError("the episode is over (or never began): call reset() first")
        a = int(action)
        if not 0 <= a < self._n_actions or a != action:
            raise ValueError(f"action {action!r} is outside the action space {self.action_space}")
        w = self.world
        w.step(a, self.np_random)
        self._last_action = a
        terminated, truncated = w.terminated(), w.truncated()
        self._running = not (terminated or truncated)
        obs = self._history.step(self._observe())
        if self._recorder is not None:
            limit = self._registered_limit()
            self._recorder.stepped(a, w.last_rewards, obs, terminated,
                                   truncated or (limit is not None and w.steps >= limit))
        info = self._info()
        if (self.world_spec.win or self.world_spec.loss) and not self._running:  # as declared ([end] win, loss)
            info["outcome"] = w.outcome()
            info["won"] = info["outcome"] == "win"
        return obs, w.last_rewards[0], terminated, truncated, info

    @property
    def records_decisions(self) -> bool:
        """Whether the env records its games (and so its policy's decisions): then `decided` is worth calling."""
        return self._recorder is not None

    def decided(self, output: "PolicyOutput", mask: np.ndarray | None = None) -> None:
        """The policy's output for the next step (a batch of one), recorded as its decision when traced."""
        if self._recorder is not None:
            self._recorder.decided(output, mask)

    def trace_info(self, info: Mapping[str, Any] | None) -> None:
        """The begin info of the games a traced env records from its next reset on."""
        if self._recorder is None:
            raise RuntimeError("trace_info: this env records no games (it was built without trace_writer)")
        self._recorder.begin_info = info

    def _registered_limit(self) -> int | None:
        """The step limit of the id gym.make built this env from: its TimeLimit wrapper truncates there,
        and the records say so (gym.make leaves max_episode_steps out of the unwrapped env's spec; a
        max_episode_steps= given to gym.make is not seen here)."""
        if self.spec is None or self.spec.id not in gym.registry:
            return None
        return gym.registry[self.spec.id].max_episode_steps

    def close(self, status: str = "finished") -> None:
        """Close the env; a traced env writes what it kept and closes its run with `status` (finished,
        or interrupted / failed when the caller stops it early)."""
        if self._recorder is not None:
            recorder, self._recorder = self._recorder, None
            recorder.close(status)
        super().close()

    def _observe(self) -> Any:
        return self.world.observation()

    def _info(self) -> dict[str, Any]:
        info: dict[str, Any] = {"t": self.world.steps}
        mask = self.world.action_mask()
        if mask is not None:
            info["action_mask"] = mask
        return info

    def render(self) -> str | np.ndarray | None:
        last = None if self._last_action is None else self.world_spec.action_names[self._last_action]
        return render_world(self.world, self.render_mode, self._painter, last)


def painter_for(spec: WorldSpec, render_mode: str | None) -> DeclaredPainter | None:
    """The image painter of render_mode "rgb_array" (a ValueError for a mode the env lacks)."""
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}")
    if render_mode == "rgb_array" and spec.board is None:
        raise ValueError(f"{spec.path}: render_mode 'rgb_array' draws the [board]; the spec has none")
    return DeclaredPainter(spec.board) if render_mode == "rgb_array" else None


def render_world(world: DeclaredWorld, render_mode: str | None, painter: DeclaredPainter | None,
                 last_actions: str | None) -> str | np.ndarray | None:
    """The board now: an image ("rgb_array"), or text ("ansi": the last actions' names, then the board
    with its marks, or the atoms that are set when the spec has no board)."""
    board = world.spec.board
    if painter is not None:
        return painter(world.marked_cells(), board.mark_colors, world.pieces_now())
    if render_mode != "ansi":
        return None
    head = f"  ({last_actions})\n" if last_actions is not None else "\n"
    if board is None:
        return head + "\n".join(f"{k}: {v}" for k, v in world.engine.interpretation(0).items()) + "\n"
    return head + board.text(world.marked_cells())


def observation_space(spec: WorldSpec) -> spaces.Space[Any]:
    """The space of an observation of `spec`, the earlier ones (`[observation] previous`) included."""
    return stacked_space(_one_observation_space(spec), spec.previous)


def _one_observation_space(spec: WorldSpec) -> spaces.Space[Any]:
    parts = spec.parts
    if spec.space == "Discrete":
        return spaces.Discrete(int(np.prod([len(p.atoms) for p in parts])))
    if spec.space == "MultiDiscrete":
        return spaces.MultiDiscrete([len(p.atoms) for p in parts])
    if spec.space == "Box":
        bounds = [np.full((p.width, 2), p.low_high, np.float32) for p in parts]
        low_high = np.concatenate(bounds)
        return spaces.Box(low_high[:, 0], low_high[:, 1], dtype=np.float32)
    return spaces.Dict({p.name: spaces.Discrete(len(p.atoms)) if p.is_discrete else spaces.Box(*p.low_high, (p.width,), np.float32) for p in parts})
