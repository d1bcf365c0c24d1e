-- Actions per win: how many episodes the learner won, their mean length in steps and, over the won games whose
-- steps were recorded (a training run traces only some games: traced_wins), the mean number of learner actions.
-- needs games : the learner's steps in won games
-- param win str = 'win' : the outcome that counts as a win
-- param learner str = '%' : the agents whose step rows are learner actions (SQL LIKE, e.g. red-agent-%)
SELECT count(*) AS wins, avg(e.steps) AS steps_per_win, count(a.actions) AS traced_wins,
       avg(a.actions) AS actions_per_win
FROM episodes e
LEFT JOIN (SELECT episode, count(*) AS actions FROM steps WHERE agent LIKE $learner GROUP BY episode) a
       ON a.episode = e.episode
WHERE e.outcome = $win
