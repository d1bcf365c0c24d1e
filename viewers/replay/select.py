"""Which episodes of a run to replay: one, a list or range, or the first N with an outcome; by default the
traced evaluation games of a training run (training-run contract, docs/store.md), else every episode
that was played (steps > 0)."""
from __future__ import annotations

from dataclasses import dataclass

from tracelab.store.names import unknown_name_message
from tracelab.store.reader import RunConnection

OUTCOMES = ("win", "loss", "draw", "truncated", "aborted",          # a game's, for red
            "converged", "stopped", "failed", "interrupted")            # a reasoning's (docs/store.md)
# kind from the episode's begin info (NULL for runs that are not training runs)
_KIND = "json_extract_string(begin_info, '$.kind')"


@dataclass(frozen=True)
class EpisodeIds:
    """Episode ids as inclusive ranges, never expanded: `--episodes 0-99999999999` is two numbers, and
    what it names is checked against the run's own episodes (select_episodes)."""
    ranges: tuple[tuple[int, int], ...]

    @classmethod
    def of(cls, *ids: int) -> "EpisodeIds":
        return cls(tuple((i, i) for i in ids))

    def __contains__(self, episode: object) -> bool:
        return isinstance(episode, int) and any(lo <= episode <= hi for lo, hi in self.ranges)

    def missing(self, found: list[int], shown: int = 5) -> list[str]:
        """The first `shown` runs of ids these ranges name that are not in `found` (sorted ids of the
        run inside the ranges), as '7' or '13-99999999999'; bounded by the run, not by the ranges."""
        gaps: list[str] = []
        for lo, hi in _merged(self.ranges):
            at = lo
            for e in (e for e in found if lo <= e <= hi):
                if e > at:
                    gaps.append(_span(at, e - 1))
                at = e + 1
            if at <= hi:
                gaps.append(_span(at, hi))
            if len(gaps) >= shown:
                break
        return gaps[:shown]


@dataclass(frozen=True)
class EpisodeFilter:
    episodes: EpisodeIds | None = None   # explicit ids (--episode, --episodes)
    outcome: str | None = None
    limit: int | None = None


_MAX_ID = (1 << 63) - 1  # episode ids are BIGINT in the store


def parse_episodes(text: str) -> EpisodeIds:
    """'3', '0-9', '1,4,7-9' -> the ranges they name."""
    ranges: list[tuple[int, int]] = []
    for part in text.split(","):
        part = part.strip()
        lo, dash, hi = part.partition("-")
        try:
            first, last = int(lo), int(hi if dash else lo)
        except ValueError:
            raise ValueError(f"bad episode list {text!r}: expected ids and ranges like 0-9,12") from None
        if not 0 <= first <= _MAX_ID or not 0 <= last <= _MAX_ID:
            raise ValueError(f"bad episode id in {part!r}: ids are from 0 to {_MAX_ID}")
        if last < first:
            raise ValueError(f"bad episode range {part!r}: the end is before the start")
        ranges.append((first, last))
    return EpisodeIds(tuple(ranges))


def _merged(ranges: tuple[tuple[int, int], ...]) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for lo, hi in sorted(ranges):
        if out and lo <= out[-1][1] + 1:
            out[-1] = (out[-1][0], max(out[-1][1], hi))
        else:
            out.append((lo, hi))
    return out


def _span(lo: int, hi: int) -> str:
    return str(lo) if lo == hi else f"{lo}-{hi}"


def is_training_run(con: RunConnection) -> bool:
    rows = con.execute(f"SELECT count(*) FROM episodes WHERE {_KIND} = 'eval'").fetchall()
    return rows[0][0] > 0


def select_episodes(con: RunConnection, f: EpisodeFilter, exclude: set[int] | None = None) -> list[int]:
    """The ended or running episodes the filter picks (ended ones only when no id is given), in id order.
    Raises ValueError naming what is missing when explicit ids are not in the run."""
    if f.outcome is not None and f.outcome not in OUTCOMES:
        raise ValueError(unknown_name_message("outcome", f.outcome, OUTCOMES, where=""))
    where = ["TRUE"]
    params: list[object] = []
    if f.episodes is not None:
        where.append("EXISTS (SELECT 1 FROM (SELECT unnest(?) AS lo, unnest(?) AS hi) "
                     "WHERE episode BETWEEN lo AND hi)")
        params += [[lo for lo, _ in f.episodes.ranges], [hi for _, hi in f.episodes.ranges]]
    else:
        where.append("ended AND steps > 0")
        if is_training_run(con):
            where.append(f"{_KIND} = 'eval'")
    if f.outcome is not None:
        where.append("outcome = ?")
        params.append(f.outcome)
    rows = con.execute(f"SELECT episode FROM episodes WHERE {' AND '.join(where)} ORDER BY episode",
                       params).fetchall()
    found = [e for (e,) in rows if not exclude or e not in exclude]
    if f.episodes is not None and f.outcome is None:
        missing = f.episodes.missing([e for (e,) in rows])
        if missing:
            known = [e for (e,) in con.execute("SELECT episode FROM episodes ORDER BY 1 LIMIT 20").fetchall()]
            raise ValueError(f"no episode {', '.join(missing)} in this run (episodes: "
                             f"{', '.join(map(str, known)) or 'none'}{' ...' if len(known) == 20 else ''})")
    return found[:f.limit] if f.limit is not None else found


def longest_episode(con: RunConnection, episodes: list[int]) -> int:
    """The most steps among these episodes (0 when none has any): where the replay's step axes end."""
    rows = con.execute("SELECT coalesce(max(steps), 0) FROM episodes WHERE list_contains(?, episode)",
                       [episodes]).fetchall()
    return int(rows[0][0])
