-- Rule firings per episode: how many bound changes each rule made in each episode, most first.
-- param episode int = null : only this episode (default: every episode)
SELECT episode, rule, count(*) AS firings, min(t) AS first_t, max(t) AS last_t
FROM firings
WHERE CAST($episode AS BIGINT) IS NULL OR episode = $episode
GROUP BY episode, rule
ORDER BY episode, firings DESC, rule
