"""The DQN update as a reader expects it (CleanRL's dqn.py): a torch.nn.Module Q-network and its target copy,
autograd, torch.optim.Adam, the TD target and the loss in plain sight: the learner to read and change
(docs/training.md, "The learner"). tracelab/train/learner.py computes the same update for the method's
one-layer network by hand, several times faster (tests/test_learners.py holds the two equal). The network
is the one tracelab/train/qnet.py describes (`NetSpec`): its layers and initial weights are read from
there, so both learners train the same network. A transition's `discount` is γ^k of the steps it spans,
0 where the episode or the agent ended."""
from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from tracelab.train.learner_protocol import RunningLoss
from tracelab.train.qnet import NetSpec, draw_weights
from tracelab.train.replay import ReplayBuffer


class DuelingQ(nn.Module):
    """Q(s, a) = V(s) + A(s, a) - mean_a A(s, a) on a shared trunk (Wang et al., 2016)."""

    def __init__(self, trunk: nn.Module, value: nn.Linear, advantage: nn.Linear) -> None:
        super().__init__()
        self.trunk, self.value, self.advantage = trunk, value, advantage

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.trunk(x)
        advantage = self.advantage(h)
        return self.value(h) + advantage - advantage.mean(dim=1, keepdim=True)


def make_q_network(spec: NetSpec, generator: torch.Generator | None = None) -> nn.Module:
    """The module `spec` describes: a Linear and a Tanh per hidden layer, then one Q-value per action (or
    the dueling head), holding `draw_weights(spec, generator)`; loading them is strict, so the module's
    parameter names are the description's."""
    linears = [nn.Linear(fan_in, fan_out) for _, fan_in, fan_out in spec.linears()]
    heads = 2 if spec.dueling else 1
    trunk = [m for layer in linears[:-heads] for m in (layer, nn.Tanh())]
    net = DuelingQ(nn.Sequential(*trunk), *linears[-2:]) if spec.dueling else nn.Sequential(*trunk, linears[-1])
    net.load_state_dict(draw_weights(spec, generator))
    return net


class DQN:
    """Online and target Q-networks, Adam, the replay buffer, and the update (any nn.Module mapping
    observations [B, D] to Q-values [B, A] will do)."""

    def __init__(self, q_network: nn.Module, buffer: ReplayBuffer, *, lr: float, double_dqn: bool = False) -> None:
        self.q_network, self.buffer, self.double_dqn = q_network, buffer, double_dqn
        self.target_network = copy.deepcopy(q_network).requires_grad_(False)
        self.optimizer = torch.optim.Adam(q_network.parameters(), lr=lr)
        self.updates = 0
        self.losses = RunningLoss()  # the mean since the last take_loss()
        self._last_q: torch.Tensor | None = None  # Q(s) of the last minibatch

    def update(self, rng: np.random.Generator) -> None:
        data = self.buffer.sample_batch(rng)
        obs, actions, rewards, next_obs, discounts = (torch.from_numpy(x) for x in data[:5])
        # --mask: 0 on the actions the shield allows in s', a large negative number on the others
        penalty = 0.0 if data.next_penalty is None else torch.from_numpy(data.next_penalty)
        with torch.no_grad():
            next_q = self.target_network(next_obs) + penalty
            if self.double_dqn:  # the online network picks a', the target network values it
                best_next = (self.q_network(next_obs) + penalty).argmax(dim=1, keepdim=True)
                next_value = next_q.gather(1, best_next)
            else:
                next_value = next_q.max(dim=1, keepdim=True).values
            td_target = rewards + discounts * next_value
        q = self.q_network(obs)
        loss = self.loss(q, actions, td_target)
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        self.losses.add(loss)
        self._last_q = q.detach()
        self.updates += 1

    def loss(self, q: torch.Tensor, actions: torch.Tensor, td_target: torch.Tensor) -> torch.Tensor:
        """The method's loss: Smooth L1 between Q(s, a) of the taken actions and the TD target. `q` is
        Q(s, ·) [B, A], so a subclass can add terms over every action (docs/training.md, "A new loss")."""
        return F.smooth_l1_loss(q.gather(1, actions), td_target)

    def sync_target(self) -> None:
        self.target_network.load_state_dict(self.q_network.state_dict())

    def take_loss(self) -> float | None:
        return self.losses.take()

    def q_max_mean(self) -> float | None:
        return None if self._last_q is None else float(self._last_q.amax(dim=1).mean())

    def online_weights(self) -> dict[str, torch.Tensor]:
        return dict(self.q_network.state_dict())  # detached, sharing the parameters' memory

    # ---- checkpoints: Adam's moments by parameter name, so a checkpoint can be checked before it is used
    def state(self) -> dict[str, Any]:
        adam = {name: {"step": float(s["step"]), "exp_avg": s["exp_avg"].clone(), "exp_avg_sq": s["exp_avg_sq"].clone()}
                for name, p in self.q_network.named_parameters() if (s := self.optimizer.state.get(p))}
        return {"online": copy.deepcopy(self.q_network.state_dict()), "adam": adam,
                "target": copy.deepcopy(self.target_network.state_dict()),
                "updates": self.updates, "buffer": self.buffer.state(), **self.losses.state(),
                "last_q": None if self._last_q is None else self._last_q.clone()}

    def load_state(self, st: dict[str, Any]) -> None:
        self.q_network.load_state_dict(st["online"])
        self.target_network.load_state_dict(st["target"])
        names = [name for name, _ in self.q_network.named_parameters()]
        opt = self.optimizer.state_dict()
        opt["state"] = {names.index(name): {"step": torch.tensor(float(s["step"])), "exp_avg": s["exp_avg"],
                                            "exp_avg_sq": s["exp_avg_sq"]} for name, s in st["adam"].items()}
        self.optimizer.load_state_dict(opt)
        self.updates = int(st["updates"])
        self.buffer.load_state(st["buffer"])
        self.losses.load_state(st)
        self._last_q = st["last_q"]


class DecomposedDQN(DQN):
    """Reward decomposition (Juozapaitis et al. 2019, drQ): the network has one Q head per reward term
    (`NetSpec.terms`), Q is their sum, and each head learns the expected return of its own term, all heads
    bootstrapping from the one greedy action of the summed target Q: for term k,
    y_k = r_k + discount * Q_target,k(s', argmax_a' Σ_j Q_target,j(s', a')). Summed over the terms, the targets
    are the ordinary DQN target (the terms' rewards sum to the reward). The loss is the sum over the terms of
    the method's Smooth L1. The buffer keeps each transition's reward by term (ReplayBuffer(reward_terms=K))."""

    def __init__(self, q_network: nn.Module, buffer: ReplayBuffer, *, lr: float, double_dqn: bool = False) -> None:
        super().__init__(q_network, buffer, lr=lr, double_dqn=double_dqn)
        self.terms, self.actions = buffer.reward_terms, buffer.n_actions

    def q_terms(self, network: nn.Module, obs: torch.Tensor) -> torch.Tensor:
        """Q-values by term [B, K, A]."""
        return network(obs).view(len(obs), self.terms, self.actions)

    def update(self, rng: np.random.Generator) -> None:
        data = self.buffer.sample_batch(rng)
        obs, actions, rewards, next_obs, discounts = (torch.from_numpy(x) for x in data[:5])  # rewards [B, K]
        penalty = 0.0 if data.next_penalty is None else torch.from_numpy(data.next_penalty)
        with torch.no_grad():
            next_terms = self.q_terms(self.target_network, next_obs)
            chooser = self.q_terms(self.q_network, next_obs) if self.double_dqn else next_terms
            best_next = (chooser.sum(dim=1) + penalty).argmax(dim=1)            # a' of the summed Q [B]
            next_value = next_terms[torch.arange(len(obs)), :, best_next]       # [B, K]
            td_target = rewards + discounts * next_value
        q_terms = self.q_terms(self.q_network, obs)
        taken = q_terms.gather(2, actions.unsqueeze(1).expand(-1, self.terms, 1)).squeeze(2)  # [B, K]
        loss = F.smooth_l1_loss(taken, td_target, reduction="none").mean(dim=0).sum()
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        self.losses.add(loss)
        self._last_q = q_terms.detach().sum(dim=1)
        self.updates += 1
