"""Every setting of a training run in one dataclass, with the method's DQN defaults (docs/training.md)
except the reward scale, whose default is the one measured to learn (the method's is one flag away).

`TrainConfig` is what a run stores (meta `config`) and what a checkpoint restores; the CLI builds its
flags from the fields' metadata, so a new hyperparameter is one field here and nothing else."""
from __future__ import annotations

import math
from dataclasses import MISSING, asdict, dataclass, field, fields
from typing import Any

from tracelab.engine.kernel_names import KERNELS as ENGINE_KERNELS
from tracelab.train.qnet import NetSpec, parse_hidden
from tracelab.train.reward_scale import LEARNING_REWARD_SCALE, METHOD_REWARD_SCALE
from tracelab.validation import Mismatch, Nullable, OptionalKey, Spec


LEARNERS = ("auto", "fused", "readable")
LEARNER_FILES = {"fused": "tracelab/train/learner.py", "readable": "tracelab/train/dqn.py"}

# torch CPU threads: one is fastest for these networks; past this many a stranger's config (a checkpoint, a
# sweep file) is asking the system for threads it cannot start ("can't start new thread" at 100,000)
MAX_THREADS = 256


def _opt(help: str, flag: str | None = None, **kw: Any) -> Any:
    """A field with its CLI help; the default goes in `default=`. `flag`: the documented flag when it is not
    the field's name (CleanRL's names, the field's conventions; the field's own name stays a hidden alias,
    and checkpoints keep storing the field name)."""
    return field(metadata={"help": help, "flag": flag}, **kw)


# fields an earlier TrainConfig had for the war game's scenario: a world's params now (its registration reads
# them from an earlier run's config: gridwar_scenarios.ScenarioTraining.given); a stored config holding them
# still loads, without them
RETIRED_FIELDS = {"scenario": str, "non_markov": bool, "agents": Nullable(int), "opponent_p": float,
                  "eval_p": float}

# RuleSim's trainer's flags, gone with their fields (an earlier run's config that holds them still loads:
# from_dict drops them): `train` refuses each in one line, saying why
RETIRED_FLAGS = {
    "--split-networks": "training runs through the world's spec with one network for every agent (RuleSim's "
                        "trainer had one for the fast and one for the slow agents)",
    "--backend": "training plays the world's spec on the rule engine; RefSim, the hand-written simulator, is the "
                 "oracle of the differential tests and `bench env`",
}


@dataclass
class TrainConfig:
    # ---- what is trained ----
    slow_every_step: bool = _opt("the slow agent decides on every step, each transition one step long; the "
                                 "game ignores its choices on steps where it may not act, and nothing in a "
                                 "Markov observation says which steps those are (default: it decides only "
                                 "where it may act, one transition spanning its two-step move)", default=False)
    kernel: str = _opt("the rule engine's kernel: auto (lanes from 64 worlds, else "
                       "counting, stepped with the game as one compiled call), counting, lanes, or compiled "
                       "(built in the "
                       "background while training starts on the counting kernel, unless `tracelab compile` "
                       "built it ahead; docs/engine-api.md). Results are the same with every kernel",
                       default="auto")
    steps: int = _opt("training steps (world-steps: env transitions)", flag="total-timesteps", default=200_000)
    seed: int = _opt("seed of everything (network init, exploration, replay sampling, envs)", default=0)
    torch_deterministic: bool = _opt("torch uses deterministic algorithms only "
                                     "(torch.use_deterministic_algorithms; --no-torch-deterministic lifts it)",
                                     default=True)
    envs: int = _opt("worlds stepped together (the batched env; from 64 on the rule engine runs its lanes "
                     "kernel, ~2x cheaper per world-step); one update per world-step either way",
                 flag="num-envs", default=64)
    mask: bool = _opt("act only among the shield's allowed actions (off in the method)", default=False)
    # ---- the method's DQN ----
    hidden: str = _opt("hidden layer widths, tanh layers, comma-separated: 64 (the method's), 64,64 (two layers)",
                       default="64")
    learner: str = _opt("the update: fused (hand-written, several times faster; one hidden layer, no "
                        "--double-dqn or --dueling), readable (autograd + torch.optim.Adam, tracelab/train/dqn.py; "
                        "any network), or auto (fused where it applies, else readable)", default="auto")
    double_dqn: bool = _opt("Double DQN: the online network picks the next action, the target network values it "
                            "(the readable learner)", default=False)
    dueling: bool = _opt("a dueling head: Q = V(s) + A(s, a) - mean A (the readable learner)", default=False)
    decompose: bool = _opt("reward decomposition: one Q head per reward term of a spec world's [reward], each "
                           "learning its term's expected return, Q their sum (the readable learner; train --env)",
                           default=False)
    lr: float = _opt("Adam learning rate", flag="learning-rate", default=5e-4)
    gamma: float = _opt("discount", default=0.99)
    batch: int = _opt("minibatch size", flag="batch-size", default=128)
    buffer: int = _opt("replay buffer capacity (transitions)", flag="buffer-size", default=50_000)
    target_every: int = _opt("copy the online network to the target network every this many steps",
                             flag="target-network-frequency", default=2_000)
    eps_start: float = _opt("epsilon until --eps-decay-start of training", default=1.0)
    eps_end: float = _opt("epsilon from --eps-decay-end of training on", default=0.02)
    eps_decay_start: float = _opt("fraction of training where epsilon starts to fall", default=0.25)
    eps_decay_end: float = _opt("fraction of training where epsilon reaches --eps-end", default=0.875)
    explore_scripted: float = _opt("fraction of the exploring (epsilon) actions taken from the scripted base "
                                   "policy played for red (a move towards blue's base when one exists; in "
                                   "the advanced scenario it shoots first) instead of uniformly at random. "
                                   "Q-learning is off-policy, so the rewards and the target are unchanged; "
                                   "only what the buffer sees is. 0 in the method; 0.5 lets 5v5 find a win "
                                   "(docs/training.md)", default=0.0)
    updates_per_step: float = _opt("gradient steps per world-step, per network", default=1.0)
    warmup: int = _opt("random steps before the first update", flag="learning-starts", default=1_000)
    reward_scale: float = _opt("the learner's rewards are the game's times this (returns and Q-values are "
                               "logged in the game's units). The default 0.01 learns the 1v1 base scenario "
                               "in 200,000 steps; the method's 1 (--reward-scale 1) did not in 760,000: the "
                               "game's rewards (250, 400) lie far outside Smooth L1's quadratic zone "
                               "(|error| < 1), where its gradient is capped, so Q-values crawl "
                               "(docs/training.md)", default=LEARNING_REWARD_SCALE)
    # ---- evaluation and logging ----
    eval_every: int = _opt("evaluate every this many steps (0: only at the end)", default=20_000)
    eval_games: int = _opt("games per evaluation", default=500)
    trace_eval_games: int = _opt("evaluation games traced in full (change rows) per evaluation",
                                 default=5)
    eval_envs: int = _opt("worlds stepped together in evaluations", default=64)
    log_every: int = _opt("write training metrics every this many steps", default=1_000)
    checkpoint_every: int = _opt("write a checkpoint every this many steps (0: only at the end)",
                                 default=50_000)
    threads: int = _opt("torch CPU threads (one is fastest for this network on 2 cores)", default=1)

    def __post_init__(self) -> None:
        problems = []
        for name in ("steps", "envs", "batch", "buffer", "target_every", "eval_games",
                     "eval_envs", "log_every", "threads"):
            if getattr(self, name) < 1:
                problems.append(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.threads > MAX_THREADS:
            problems.append(f"threads must be at most {MAX_THREADS}, got {self.threads}")
        for name in ("warmup", "eval_every", "trace_eval_games", "checkpoint_every"):
            if getattr(self, name) < 0:
                problems.append(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("eps_start", "eps_end", "eps_decay_start", "eps_decay_end",
                     "explore_scripted"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                problems.append(f"{name} must be in [0, 1], got {v}")
        if self.eps_decay_end < self.eps_decay_start:
            problems.append("eps_decay_end must not come before eps_decay_start")
        if not (0.0 < self.gamma <= 1.0) or not (self.lr > 0 and math.isfinite(self.lr)):
            problems.append(f"gamma must be in (0, 1] and lr > 0, got {self.gamma}, {self.lr}")
        if not (self.reward_scale > 0 and math.isfinite(self.reward_scale)):
            problems.append(f"reward_scale must be a positive number, got {self.reward_scale}")
        if self.updates_per_step < 0:
            problems.append(f"updates_per_step must be >= 0, got {self.updates_per_step}")
        if self.kernel not in ENGINE_KERNELS:
            problems.append(f"kernel must be one of {', '.join(ENGINE_KERNELS)}, got {self.kernel!r}")
        if isinstance(self.hidden, int) and not isinstance(self.hidden, bool):  # one width, as configs had it
            self.hidden = str(self.hidden)
        try:
            parse_hidden(self.hidden)
        except ValueError as e:
            problems.append(str(e))
        if self.learner not in LEARNERS:
            problems.append(f"learner must be one of {', '.join(LEARNERS)}, got {self.learner!r}")
        if self.decompose and self.dueling:
            problems.append("--decompose and --dueling: a decomposed network has one plain head per reward term")
        elif self.learner == "fused" and not problems and self.fused_refusal():
            problems.append(f"learner fused {self.fused_refusal()}; use --learner readable (or auto)")
        if problems:
            raise ValueError("; ".join(problems))

    @property
    def hidden_sizes(self) -> tuple[int, ...]:
        return parse_hidden(self.hidden)

    def fused_refusal(self) -> str | None:
        """Why the fused learner cannot run this config (None: it can): it is written for one tanh hidden
        layer and the plain max target."""
        given = [flag for flag, on in (("--double-dqn", self.double_dqn), ("--dueling", self.dueling),
                                       ("--decompose", self.decompose),
                                       (f"--hidden {self.hidden}", len(self.hidden_sizes) > 1)) if on]
        if not given:
            return None
        return f"supports one hidden layer without --double-dqn, --dueling or --decompose (given: {', '.join(given)})"

    def learner_choice(self) -> str:
        """The learner a run uses, fused or readable (auto: fused unless it refuses the config, learner_text)."""
        if self.learner != "auto":
            return self.learner
        return "readable" if self.fused_refusal() else "fused"

    def network(self, inputs: int, actions: int, reward_terms: tuple[str, ...] = ()) -> NetSpec:
        """The Q-network this config trains on `inputs` observation features and `actions` actions;
        `reward_terms`: the world's, one head each with --decompose (ValueError when it has none)."""
        if self.decompose and not reward_terms:
            raise ValueError("--decompose needs a world whose reward is split into terms: a spec world's "
                             "[reward] (train --env FILE.toml; the war game's 1v1 base: train --env "
                             "rules/gridworld/war.toml --decompose)")
        return NetSpec(inputs, self.hidden_sizes, actions, self.dueling, tuple(reward_terms) if self.decompose else ())

    def learner_text(self) -> str:
        """Which learner trains and why, as `train`'s first line says it (docs/training.md, "The learner")."""
        kind = self.learner_choice()
        if self.learner != "auto":
            return f"the {kind} learner ({LEARNER_FILES[kind]}, --learner {kind})"
        if kind == "readable":
            return f"the readable learner ({LEARNER_FILES['readable']}; --learner auto: the fused one " \
                   f"{self.fused_refusal()})"
        return (f"the fused learner ({LEARNER_FILES['fused']}, dqn.py's update written by hand; --learner auto takes "
                f"it for the method's network; an edited dqn.py trains with --learner readable)")

    def epsilon(self, step: int) -> float:
        """The method's schedule: eps_start until eps_decay_start of training, then linear down to eps_end
        at eps_decay_end, then eps_end."""
        a, b = self.eps_decay_start * self.steps, self.eps_decay_end * self.steps
        if step <= a:
            return self.eps_start
        if step >= b:
            return self.eps_end
        return self.eps_start + (self.eps_end - self.eps_start) * (step - a) / (b - a)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TrainConfig":
        known = {f.name for f in fields(cls)}  # a field retired since (RETIRED_FIELDS, split_networks, ...) is dropped
        d = {k: v for k, v in d.items() if k in known}
        if "reward_scale" not in d:     # written before the flag: the learner saw the game's rewards
            d["reward_scale"] = METHOD_REWARD_SCALE
        return cls(**d)


_FIELD_SCHEMAS = {"int": int, "float": float, "bool": bool, "str": str}


def config_schema() -> dict[str, Any]:
    """The type of every field, to check a config read from a file (a checkpoint) before building it:
    absent fields take their defaults (written before they existed)."""
    schema = {f.name: OptionalKey(_FIELD_SCHEMAS[str(f.type)]) for f in fields(TrainConfig)}
    schema.update({name: OptionalKey(kind) for name, kind in RETIRED_FIELDS.items()})
    schema["hidden"] = OptionalKey(HiddenField())  # one width, as a number, before --hidden took layers
    return schema


class HiddenField(Spec):
    expected = "layer widths as a string (64,64) or one width as an integer"

    def check(self, value: Any, where: str) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, str)):
            raise Mismatch(where, self.expected, value)


@dataclass(frozen=True)
class ConfigField:
    """One field as the CLI shows it: `flag` the documented flag (without --), `alias` the field's own
    name as a flag when that differs (accepted, not listed)."""
    name: str
    type: Any
    default: Any
    help: str
    flag: str
    alias: str | None


def config_fields() -> list[ConfigField]:
    """Every field, for building CLI flags."""
    out = []
    for f in fields(TrainConfig):
        default = f.default if f.default is not MISSING else None
        own = f.name.replace("_", "-")
        flag = f.metadata.get("flag") or own
        out.append(ConfigField(f.name, f.type, default, f.metadata.get("help", ""), flag,
                               own if flag != own else None))
    return out


def flag_of(name: str) -> str:
    """The documented flag of a field, e.g. steps -> --total-timesteps (messages name what the user types)."""
    return "--" + next((c.flag for c in config_fields() if c.name == name), name.replace("_", "-"))
