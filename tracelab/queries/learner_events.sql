-- Learner events per episode: how often the learner was shot, tried an unsafe move and made an invalid action
-- (each a label set to [1,1] on a learner agent; the default label names are those of rules/gridworld/game.rules).
-- needs board : the events of the grid game's agents
-- param learner str = 'red-agent-%' : learner agents (SQL LIKE on the node)
-- param shot_label str = 'gotShot' : the label set when an agent is hit
-- param unsafe_label str = 'unsafe' : the label set for an unsafe or illegal move
-- param invalid_label str = 'invalid' : the label set for an invalid action (shooting with no ammo)
WITH ev AS (
  SELECT episode,
         count(*) FILTER (label = $shot_label) AS shot,
         count(*) FILTER (label = $unsafe_label) AS unsafe,
         count(*) FILTER (label = $invalid_label) AS invalid
  FROM changes
  WHERE node LIKE $learner AND new_lower = 1 AND new_upper = 1
    AND label IN ($shot_label, $unsafe_label, $invalid_label)
  GROUP BY episode
)
SELECT e.episode, e.outcome, e.steps, coalesce(ev.shot, 0) AS shot, coalesce(ev.unsafe, 0) AS unsafe,
       coalesce(ev.invalid, 0) AS invalid
FROM episodes e LEFT JOIN ev ON ev.episode = e.episode
ORDER BY e.episode
