-- Hiding behind a mountain: per episode, the timesteps a learner agent ended next to a mountain that stood between it and an enemy agent on the same row or column (cells named c{row}_{col}, a spec's default, or nodes numbered y*width+x, RuleSim's).
-- needs board : agents, cells and mountains of the grid game
-- param learner str = 'red-agent-%' : learner agents (SQL LIKE)
-- param enemy str = 'blue-agent-%' : enemy agents (SQL LIKE)
-- param loc_label str = 'atLoc' : the location label, loc(agent, cell)
-- param mountain_label str = 'mountain' : the mountain label, mountain(cell)
-- param width int = 8 : grid width (cells numbered y*width+x only)
WITH arrivals AS (       -- an agent is on a cell from the change that set loc(agent, cell) to [1,1]
  SELECT c.episode, c.t, c.seq, a.arg0 AS agent, a.arg1 AS cell
  FROM changes c JOIN atoms a ON a.atom = c.atom_id
  WHERE c.label = $loc_label AND c.new_lower = 1 AND c.new_upper = 1
    AND (a.arg0 LIKE $learner OR a.arg0 LIKE $enemy)
),
mountains AS (           -- a spec's board states its mountains as static facts; RuleSim's runs set them
  SELECT a.node AS cell FROM facts f JOIN atoms a ON f.literal = a.text || ':[1,1]'
  WHERE a.label = $mountain_label AND f.static
  UNION
  SELECT node FROM changes WHERE label = $mountain_label AND new_lower = 1 AND new_upper = 1
),
places AS (              -- a cell's x, y: c{row}_{col} (the row is y, counted down) or y*width+x
  SELECT cell,
         coalesce(TRY_CAST(regexp_extract(cell, '^c([0-9]+)_([0-9]+)$', 2) AS INTEGER),
                  TRY_CAST(cell AS INTEGER) % $width) AS x,
         coalesce(TRY_CAST(regexp_extract(cell, '^c([0-9]+)_([0-9]+)$', 1) AS INTEGER),
                  TRY_CAST(cell AS INTEGER) // $width) AS y
  FROM (SELECT cell FROM arrivals UNION SELECT cell FROM mountains)
),
ticks AS (SELECT DISTINCT episode, t FROM raw.changes),
agents AS (SELECT DISTINCT episode, agent FROM arrivals),
pos AS (                 -- each agent's cell at the end of every timestep of its episode
  SELECT k.episode, k.t, g.agent, l.cell
  FROM ticks k JOIN agents g ON g.episode = k.episode
  ASOF JOIN arrivals l ON l.episode = k.episode AND l.agent = g.agent AND l.t <= k.t
),
me AS (SELECT pos.*, p.x, p.y FROM pos JOIN places p USING (cell) WHERE agent LIKE $learner),
foe AS (SELECT pos.*, p.x, p.y FROM pos JOIN places p USING (cell) WHERE agent LIKE $enemy),
mtn AS (SELECT p.x, p.y FROM mountains JOIN places p USING (cell)),
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
