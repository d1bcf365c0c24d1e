-- The steps before a loss: the last n steps of every lost episode (each agent's action and reward), in order.
-- needs games : the agents' steps in lost games
-- param loss str = 'loss' : the outcome that counts as a loss
-- param n int = 5 : how many final steps
-- param learner str = '%' : which agents (SQL LIKE, e.g. red-agent-%)
SELECT episode, step, t, agent, action, reward, terminated, truncated
FROM (SELECT s.*, max(s.step) OVER (PARTITION BY s.episode) AS last_step
      FROM steps s JOIN episodes e ON e.episode = s.episode
      WHERE e.outcome = $loss AND s.agent LIKE $learner)
WHERE step > last_step - $n
ORDER BY episode, step, agent
