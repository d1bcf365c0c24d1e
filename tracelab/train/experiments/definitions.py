"""The method's experiments (docs/experiments/): what each trains, the published figure it compares
with, and its full and `--quick` budgets."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from tracelab import RULES_DIR
from tracelab.game.scenario import Rewards, Scenario, builtin_scenario
from tracelab.train.reward_scale import LEARNING_REWARD_SCALE, METHOD_REWARD_SCALE

if TYPE_CHECKING:
    from tracelab.envs.declared.env_source import EnvSource


@dataclass(frozen=True)
class Arm:
    """One training setting of an experiment (trained once per seed)."""
    label: str
    scenario: str
    agents: int | None = None
    non_markov: bool = False
    rewards: dict[str, float] = field(default_factory=dict)  # overrides of the scenario's [rewards]
    published: float | None = None                           # the method's win rate for this setting
    published_note: str = ""
    train: dict[str, Any] = field(default_factory=dict)      # TrainConfig overrides of this arm only
    # a world other than the war game: a spec file under rules/ (or a registered id) and its --env-arg values;
    # its games are counted as the world declares ([end] win / loss) and it has no opponent setting
    env: str | None = None
    env_args: dict[str, Any] = field(default_factory=dict)

    def build_world(self) -> Scenario | EnvSource:
        """What the arm trains on: the war game's scenario, or the env of a world arm."""
        if self.env is None:
            return self.build_scenario()
        # deferred: loads gymnasium, which the war game's experiments do not need
        from tracelab.envs.declared.env_source import EnvSource
        spec = RULES_DIR / self.env
        return EnvSource(str(spec) if spec.is_file() else self.env, dict(self.env_args))

    def build_scenario(self) -> Scenario:
        sc = builtin_scenario(self.scenario)
        if self.agents is not None and self.agents != sc.agents_per_team:
            sc = dataclasses.replace(sc, agents_per_team=self.agents, red_starts=None, blue_starts=None)
        if self.rewards:
            sc = dataclasses.replace(sc, rewards=dataclasses.replace(sc.rewards, **self.rewards))
        return sc

    @property
    def slug(self) -> str:
        words = "".join(c if c.isalnum() else " " for c in self.label.lower()).split()
        return "-".join(words)


@dataclass(frozen=True)
class Budget:
    seeds: int
    steps: int
    eval_games: int     # games per evaluation during training and per final evaluation
    evals: int          # evaluations over training (a learning curve's points)


@dataclass(frozen=True)
class Experiment:
    name: str
    title: str
    arms: tuple[Arm, ...]
    full: Budget
    quick: Budget
    goal: str
    train: dict[str, Any] = field(default_factory=lambda: dict(LEARNER_REWARD_SCALE))  # shared by the arms


# The experiments train with the game's rewards x 0.01 as the learner sees them (docs/training.md, "Reward
# scale"; train's default, pinned here so that a report reads the same if the default moves): at the
# game's scale Smooth L1's gradient is capped and the method's settings barely learn.
LEARNER_REWARD_SCALE = {"reward_scale": LEARNING_REWARD_SCALE}
METHODS_SETTINGS = {"reward_scale": METHOD_REWARD_SCALE}
# With five agents a team a uniformly random red never beats blue (0 of 2,000 games against p = 0.7), so
# uniform exploration never shows the learner a win: half of the exploring actions come from the scripted
# policy played for red (docs/training.md, "Scripted exploration").
SCRIPTED_EXPLORATION = {"explore_scripted": 0.5}
METHOD_1V1 = {"published": 0.976, "published_note": "97.6% after 760K steps (A100)"}  # the 1v1 figure

SHOT_BEFORE = {"got_shot": -400.0}                          # the setting whose traces showed hiding
SHOT_AFTER = {"got_shot": -200.0, "invalid": -10.0}         # the method's fix
NO_AMMO_HIGH = {"got_shot": -200.0, "invalid": -200.0}      # "a penalty of 10 (not more)": what more does
assert Rewards().got_shot == -200.0 and Rewards().invalid == -10.0  # the defaults are the method's fix

TRAP_CORRIDOR = "examples/trap_corridor.toml"  # under rules/

EXPERIMENTS: dict[str, Experiment] = {e.name: e for e in (
    Experiment(
        "1v1-base", "1v1 base scenario: win rate over training",
        (Arm("1v1 base", "base", **METHOD_1V1),
         Arm("1v1 base, the method's reward scale", "base", train=METHODS_SETTINGS, **METHOD_1V1)),
        full=Budget(seeds=3, steps=200_000, eval_games=500, evals=10),
        quick=Budget(seeds=1, steps=3_000, eval_games=40, evals=2),
        goal="method's win rate >= 97.6% against p = 0.3 with fewer than 760K steps"),
    Experiment(
        "5v5-base", "5v5 base scenario: win rate over training",
        (Arm("5v5 base", "base", agents=5, train=SCRIPTED_EXPLORATION, published=0.794,
             published_note="79.4% after 1.536M steps"),),
        full=Budget(seeds=3, steps=300_000, eval_games=500, evals=10),
        quick=Budget(seeds=1, steps=2_000, eval_games=20, evals=2),
        goal="method's win rate >= 79.4% against p = 0.3"),
    Experiment(
        "portability", "Portability: the same policies in the spec world and the hand-written simulator",
        (Arm("1v1 base", "base", published=0.976, published_note="97.6% proxy, 100% other simulators"),),
        full=Budget(seeds=3, steps=200_000, eval_games=500, evals=5),
        quick=Budget(seeds=1, steps=1_500, eval_games=30, evals=1),
        goal="win rates within 3 points and rewards within 10% between the simulators; "
             "the gap no larger than sampling noise"),
    Experiment(
        "markov-vs-nonmarkov", "Markov vs non-Markov policies in the nonmarkov scenario",
        # The arms differ only in the observation. (RuleSim's trainer also had a network per agent speed,
        # --split-networks; the spec path trains one network for every agent: docs/experiments/README.md.)
        (Arm("Markov", "nonmarkov", published=0.59, published_note="best Markov 59%, 15.51 actions per win"),
         Arm("non-Markov", "nonmarkov", non_markov=True, published=0.85,
             published_note="best non-Markov 85%, 18.01 actions per win")),
        full=Budget(seeds=3, steps=300_000, eval_games=500, evals=10),
        quick=Budget(seeds=1, steps=1_500, eval_games=20, evals=1),
        goal="non-Markov above Markov by a margin outside the seed spread",
        train={**LEARNER_REWARD_SCALE, **SCRIPTED_EXPLORATION}),  # both arms: random red wins 0% here too
    Experiment(
        "markov-vs-nonmarkov-every-step",
        "Markov vs non-Markov policies in the nonmarkov scenario, the slow agent deciding every step",
        # markov-vs-nonmarkov asks the slow agent only where it may act (even steps, not in transit), one
        # transition spanning its two-step move: that makes its decisions Markov. Here it decides every step
        # and the game ignores what it chooses on odd steps, which nothing in the current observation tells.
        (Arm("Markov", "nonmarkov", train={"slow_every_step": True}, published=0.59,
             published_note="best Markov 59%, 15.51 actions per win"),
         Arm("non-Markov", "nonmarkov", non_markov=True, train={"slow_every_step": True}, published=0.85,
             published_note="best non-Markov 85%, 18.01 actions per win")),
        full=Budget(seeds=3, steps=300_000, eval_games=500, evals=10),
        quick=Budget(seeds=1, steps=1_500, eval_games=20, evals=1),
        goal="non-Markov above Markov by a margin outside the seed spread",
        train={**LEARNER_REWARD_SCALE, **SCRIPTED_EXPLORATION}),
    Experiment(
        "trap-corridor", "A world of its own: the trap corridor (rules/examples/trap_corridor.toml)",
        # any world trains, is counted and reported as the war game is: its spec declares a win (the door) and a
        # loss (the trap, a step after it is stepped on); the arms differ in the door's reward (a param)
        (Arm("door reward 1", "", env=TRAP_CORRIDOR, env_args={"door_reward": 1.0}),
         Arm("door reward 0.2", "", env=TRAP_CORRIDOR, env_args={"door_reward": 0.2})),
        full=Budget(seeds=3, steps=5_000, eval_games=200, evals=5),
        quick=Budget(seeds=1, steps=300, eval_games=12, evals=1),
        goal="both arms learn to walk to the door: win rate 100% (the world's [end] win)",
        train={"reward_scale": 1.0}),  # the world's rewards are about 1, not hundreds as the war game's
    Experiment(
        "reward-shaping", "Reward shaping from traces: penalty for being shot 400, then 200",
        (Arm("shot -400", "advanced", rewards=SHOT_BEFORE),
         Arm("shot -200, no ammo -10", "advanced", rewards=SHOT_AFTER),
         Arm("shot -200, no ammo -200", "advanced", rewards=NO_AMMO_HIGH)),
        full=Budget(seeds=3, steps=200_000, eval_games=500, evals=5),
        quick=Budget(seeds=1, steps=1_000, eval_games=16, evals=1),
        goal="the traces' figures move as the method describes: less hiding at -200 than at -400, shooting "
             "kept with a no-ammo penalty of 10 and not with a larger one",
        train={**LEARNER_REWARD_SCALE, **SCRIPTED_EXPLORATION}),  # uniform exploration did not learn 200K
)}
