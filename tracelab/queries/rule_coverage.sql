-- Rule coverage: every rule of the program with its firings over the whole run (0: it never changed anything).
SELECT r.name AS rule, r.delay, r.immediate, count(f.seq) AS firings,
       count(DISTINCT f.episode) AS episodes, r.file, r.line
FROM rules r LEFT JOIN firings f ON f.rule = r.name
GROUP BY r.rule, r.name, r.delay, r.immediate, r.file, r.line
ORDER BY firings DESC, r.rule
