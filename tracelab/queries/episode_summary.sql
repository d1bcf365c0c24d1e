-- Episode summary: outcome, length, return, and how many changes, rule firings and actions each episode logged.
SELECT e.episode, e.world, e.outcome, e.steps, e.reward,
       coalesce(c.changes, 0) AS changes, coalesce(c.firings, 0) AS firings,
       coalesce(c.actions, 0) AS action_facts, e.started_at, e.ended_at
FROM episodes e
LEFT JOIN (SELECT episode, count(*) AS changes, count(*) FILTER (cause_kind = 2) AS firings,
                  count(*) FILTER (cause_kind = 1) AS actions
           FROM raw.changes GROUP BY episode) c ON c.episode = e.episode
ORDER BY e.episode
