"""A what-if branch beside its origin (`tracelab whatif`): each side's steps, return, outcome and return
by reward term (reward_rescore.rescore: the `returns` view), and where they first diverge (diff's
first_divergence). Both runs are read through their sandboxed connections."""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from tracelab.store.branch_origin import Origin
from tracelab.store.diff import Divergence, first_divergence
from tracelab.store.reader import RunConnection
from tracelab.store.reward_rescore import rescore


@dataclass
class Side:
    """One episode's outcome: steps, return, outcome, return by term (term -> value)."""
    name: str
    episode: int
    steps: int
    ret: float
    outcome: str | None
    by_term: dict[str, float]


@dataclass
class BranchComparison:
    origin: Origin
    original: Side
    branch: Side
    divergence: Divergence

    def to_dict(self) -> dict[str, Any]:
        return {"origin": self.origin.to_json(), "original": asdict(self.original), "branch": asdict(self.branch),
                "divergence": self.divergence.to_dict()}


def episode_side(con: RunConnection, name: str, episode: int) -> Side:
    """`episode`'s steps, return and outcome, and its return by term ({} when the run records no terms)."""
    row = con.execute("SELECT steps, reward, outcome FROM episodes WHERE episode = ?", [episode]).fetchall()
    steps, ret, outcome = row[0] if row else (0, 0.0, None)
    try:
        by_term = rescore(con, [], episode).rows[0]["by_term"]
    except KeyError:  # no reward terms recorded, or no steps
        by_term = {}
    return Side(name, episode, int(steps or 0), float(ret or 0.0), outcome, by_term)


def compare_branch(origin_con: RunConnection, origin_name: str, branch_con: RunConnection, branch_name: str,
                   origin: Origin, branch_episode: int = 0) -> BranchComparison:
    """The branch's episode beside the origin's episode it branched off."""
    d = first_divergence(origin_con, origin.episode, branch_episode, branch_con, run_names=(origin_name, branch_name))
    return BranchComparison(origin, episode_side(origin_con, origin_name, origin.episode),
                            episode_side(branch_con, branch_name, branch_episode), d)
