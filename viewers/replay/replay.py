"""Replaying a run: the chosen episodes, once (`replay_run`) or as they finish in a run being written
(`follow_run`, --live), each as one recording (recording.py: on the world's board, or the run's graph)."""
from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial

from tracelab.viewers.replay.outputs import Output
from tracelab.viewers.replay.recording import ReplayOptions, RunContext
from tracelab.viewers.replay.select import EpisodeFilter, longest_episode, select_episodes

from tracelab.store.reader import RunConnection, retrying, run_info

PREFETCH_EPISODES = 50      # episodes read from the run per batch (their change rows are held in memory)


def context_of(con: RunConnection, name: str) -> RunContext:
    """What every episode of the run shares (its board or its graph, its model)."""
    return RunContext.of(con, name)


def replay_episodes(ctx: RunContext, episodes: list[int], out: Output,
                    options: ReplayOptions | None = None) -> int:
    """Each episode as its own recording into `out`; returns how many were sent. What the episodes need
    from the run is read a batch at a time. The blueprint, sent once per output, gets step axes as long
    as the longest of these episodes (in --live, of the first game sent)."""
    last_step = 0 if out.blueprint_sent else retrying(lambda: longest_episode(ctx.con, episodes))
    for i, e in enumerate(episodes):
        if i % PREFETCH_EPISODES == 0:
            retrying(partial(ctx.prefetch, episodes[i:i + PREFETCH_EPISODES]))
        rec = out.recording(ctx.name, e)
        retrying(partial(ctx.record, e, rec, options or ReplayOptions(), blueprint=not out.blueprint_sent,
                         last_step=last_step))
        out.blueprint_sent = True
        out.finished(rec)
    return len(episodes)


def replay_run(ctx: RunContext, f: EpisodeFilter, out: Output, options: ReplayOptions | None = None) -> int:
    episodes = retrying(lambda: select_episodes(ctx.con, f))
    if not episodes:
        raise ValueError("no episode of this run matches (played episodes with steps > 0"
                         + (f", outcome {f.outcome}" if f.outcome else "") + ")")
    retrying(partial(ctx.check, options or ReplayOptions(), episodes[0]))
    n = replay_episodes(ctx, episodes, out, options)
    out.close()
    return n


def follow_run(con: RunConnection, name: str, run: str, f: EpisodeFilter, out: Output,
               options: ReplayOptions | None = None, poll_s: float = 0.5,
               on_episode: Callable[[int], None] | None = None) -> int:
    """Stream each episode the filter picks as soon as it has ended, until the run stops running.
    Returns how many were sent. The run's program is read once its first episode has ended (a run
    just started may not have published it yet)."""
    sent: set[int] = set()
    ctx: RunContext | None = None
    while True:
        running = run_info(run).status == "running"
        new = retrying(lambda: select_episodes(con, EpisodeFilter(None, f.outcome), exclude=sent))
        if f.episodes is not None:
            new = [e for e in new if e in f.episodes]
        if f.limit is not None:
            new = new[:max(f.limit - len(sent), 0)]
        if new:
            if ctx is None:
                ctx = retrying(lambda: context_of(con, name))
                retrying(partial(ctx.check, options or ReplayOptions(), new[0]))
            for e in new:
                replay_episodes(ctx, [e], out, options)
                sent.add(e)
                out.write()
                if on_episode:
                    on_episode(e)
        if (f.limit is not None and len(sent) >= f.limit) or not running:
            break
        time.sleep(poll_s)
    out.close()
    return len(sent)
