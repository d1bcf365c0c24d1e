"""Which episodes of a run to replay: one, a list or range, or the first N with an outcome; by default the
traced evaluation games of a training run (training-run contract, docs/store.md), else every episode
that was played (steps > 0)."""
from __future__ import annotations

from dataclasses import dataclass

from tracelab.store.reader import RunConnection

OUTCOMES = ("win", "loss", "draw", "truncated", "aborted")
# kind from the episode's begin info (NULL for runs that are not training runs)
_KIND = "json_extract_string(begin_info, '$.kind')"


@dataclass(frozen=True)
class EpisodeFilter:
    episodes: tuple[int, ...] | None = None   # explicit ids (--episode, --episodes)
    outcome: str | None = None
    limit: int | None = None


def parse_episodes(text: str) -> tuple[int, ...]:
    """'3', '0-9', '1,4,7-9' -> episode ids, in order, without repeats."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        lo, dash, hi = part.partition("-")
        try:
            ids = range(int(lo), int(hi) + 1) if dash else [int(part)]
        except ValueError:
            raise ValueError(f"bad episode list {text!r}: expected ids and ranges like 0-9,12") from None
        if dash and int(hi) < int(lo):
            raise ValueError(f"bad episode range {part!r}: the end is before the start")
        out += [i for i in ids if i not in out]
    return tuple(out)


def is_training_run(con: RunConnection) -> bool:
    rows = con.execute(f"SELECT count(*) FROM episodes WHERE {_KIND} = 'eval'").fetchall()
    return rows[0][0] > 0


def select_episodes(con: RunConnection, f: EpisodeFilter, exclude: set[int] | None = None) -> list[int]:
    """The ended or running episodes the filter picks (ended ones only when no id is given), in id order.
    Raises ValueError naming what is missing when explicit ids are not in the run."""
    if f.outcome is not None and f.outcome not in OUTCOMES:
        raise ValueError(f"unknown outcome {f.outcome!r}; expected one of {', '.join(OUTCOMES)}")
    where = ["TRUE"]
    params: list[object] = []
    if f.episodes is not None:
        where.append("episode IN (SELECT unnest(?))")
        params.append(list(f.episodes))
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
        missing = sorted(set(f.episodes) - {e for (e,) in rows})
        if missing:
            known = [e for (e,) in con.execute("SELECT episode FROM episodes ORDER BY 1 LIMIT 20").fetchall()]
            raise ValueError(f"no episode {', '.join(map(str, missing))} in this run (episodes: "
                             f"{', '.join(map(str, known)) or 'none'}{' ...' if len(known) == 20 else ''})")
    return found[:f.limit] if f.limit is not None else found
