-- Per-trial summary of rte_frames, for pipeline.database.store (schema version 1.0):
-- mean_rte_pct = mean t_err_pct over the trial's start frames, rte_frames = their count.
-- A joint-SMBO trial (sequence = '__joint__') pools the frames of every sequence it ran on.
UPDATE trials
SET mean_rte_pct = s.mean_rte_pct, rte_frames = s.n
FROM (
    SELECT t.study, t.algorithm, t.sequence, t.trial,
           avg(r.t_err_pct) AS mean_rte_pct, count(*)::INTEGER AS n
    FROM trials AS t
    JOIN rte_frames AS r
        ON r.study = t.study AND r.algorithm = t.algorithm AND r.trial = t.trial
        AND (t.sequence = '__joint__' OR r.sequence = t.sequence)
    GROUP BY t.study, t.algorithm, t.sequence, t.trial
) AS s
WHERE trials.study = s.study AND trials.algorithm = s.algorithm
    AND trials.sequence = s.sequence AND trials.trial = s.trial;
