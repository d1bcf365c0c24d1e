-- Hiding behind a mountain: per episode, the timesteps a learner agent ended next to a mountain that stood between it and an enemy agent on the same row or column (cells are nodes numbered y*width+x).
-- needs board : agents, cells and mountains of the grid game
-- param learner str = 'red-agent-%' : learner agents (SQL LIKE)
-- param enemy str = 'blue-agent-%' : enemy agents (SQL LIKE)
-- param loc_label str = 'atLoc' : the location label, loc(agent, cell)
-- param mountain_label str = 'mountain' : the mountain label, mountain(cell)
-- param width int = 8 : grid width
WITH arrivals AS (       -- an agent is on a cell from the change that set loc(agent, cell) to [1,1]
  SELECT c.episode, c.t, c.seq, a.arg0 AS agent, TRY_CAST(a.arg1 AS INTEGER) AS cell
  FROM changes c JOIN atoms a ON a.atom = c.atom_id
  WHERE c.label = $loc_label AND c.new_lower = 1 AND c.new_upper = 1
    AND (a.arg0 LIKE $learner OR a.arg0 LIKE $enemy)
),
mountains AS (
  SELECT DISTINCT TRY_CAST(node AS INTEGER) AS cell FROM changes
  WHERE label = $mountain_label AND new_lower = 1 AND new_upper = 1
),
ticks AS (SELECT DISTINCT episode, t FROM raw.changes),
agents AS (SELECT DISTINCT episode, agent FROM arrivals),
pos AS (                 -- each agent's cell at the end of every timestep of its episode
  SELECT k.episode, k.t, g.agent, l.cell
  FROM ticks k JOIN agents g ON g.episode = k.episode
  ASOF JOIN arrivals l ON l.episode = k.episode AND l.agent = g.agent AND l.t <= k.t
),
me AS (SELECT *, cell % $width AS x, cell // $width AS y FROM pos WHERE agent LIKE $learner),
foe AS (SELECT *, cell % $width AS x, cell // $width AS y FROM pos WHERE agent LIKE $enemy),
mtn AS (SELECT cell % $width AS x, cell // $width AS y FROM mountains),
hidden AS (
  SELECT DISTINCT me.episode, me.t, me.agent
  FROM me JOIN foe ON foe.episode = me.episode AND foe.t = me.t
  JOIN mtn ON (mtn.y = me.y AND foe.y = me.y AND abs(mtn.x - me.x) = 1
               AND mtn.x BETWEEN least(me.x, foe.x) AND greatest(me.x, foe.x) AND mtn.x <> foe.x)
           OR (mtn.x = me.x AND foe.x = me.x AND abs(mtn.y - me.y) = 1
               AND mtn.y BETWEEN least(me.y, foe.y) AND greatest(me.y, foe.y) AND mtn.y <> foe.y)
)
SELECT e.episode, e.outcome, e.steps, count(h.t) AS hidden_steps
FROM episodes e LEFT JOIN hidden h ON h.episode = e.episode
GROUP BY e.episode, e.outcome, e.steps
ORDER BY e.episode
