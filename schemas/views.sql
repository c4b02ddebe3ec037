-- adaptune results database: views. Applied after the tables are filled (tables.sql).
INSERT INTO schema_info VALUES ('views.sql', '1.1');

-- Training rows of the surrogate: one row per (algorithm, sequence, trial, frame) of the ok
-- and pruned trials of the per-sequence SMBO, with the frame's environment (e0..e9), the
-- trial's parameters (p_<name>, every algorithm's) and the target y = per-start-frame RTE [%].
-- A pruned trial has rows for the segments that end within the frames it ran: the same rows a
-- whole run would have given there (the odometry is causal), so they are kept.
-- A database without environment values (rte without --environment) or without trials still
-- gets the view, without those columns: COLUMNS() refuses a pattern that matches nothing, so
-- e0.. and p_.. come with trial and frame, which are always there (in the joins' order).
CREATE VIEW surrogate_rows AS
SELECT r.algorithm, r.sequence, COLUMNS('^(trial|frame|e[0-9]+|p_.+)$'),
       r.t_err_pct AS y
FROM rte_frames AS r
JOIN environment AS e USING (sequence, frame)
JOIN trials AS t USING (study, algorithm, sequence, trial)
WHERE r.study = 'trials' AND t.status IN ('ok', 'pruned');

-- Training rows of the portfolio selector (surrogate.rows: portfolio; pipeline.portfolio):
-- one row per (algorithm, sequence, member, frame) of the study 'portfolio', every member at
-- every frame that any member scored on that sequence, with the columns of surrogate_rows. A
-- failed member has y = its objective (the failure penalty) at all of them, so that a set that
-- fails in an environment is never chosen there; its partial rows are not used.
CREATE VIEW portfolio_rows AS
WITH frames AS (SELECT DISTINCT algorithm, sequence, frame FROM rte_frames
                WHERE study = 'portfolio'),
     members AS (SELECT * FROM trials WHERE study = 'portfolio' AND status IN ('ok', 'failed')),
     scored AS (SELECT algorithm, sequence, trial AS scored_trial, frame AS scored_frame,
                       t_err_pct FROM rte_frames WHERE study = 'portfolio')
SELECT algorithm, sequence, COLUMNS('^(trial|frame|e[0-9]+|p_.+)$'),
       CASE WHEN m.status = 'ok' THEN s.t_err_pct ELSE m.objective END AS y
FROM frames AS f
JOIN members AS m USING (algorithm, sequence)
JOIN environment AS e USING (sequence, frame)
LEFT JOIN scored AS s ON s.algorithm = f.algorithm AND s.sequence = f.sequence
     AND s.scored_trial = m.trial AND s.scored_frame = f.frame;

-- RTE per environment label: each rte_frames row with the label of its start frame.
CREATE VIEW rte_labelled AS
SELECT r.*, l.label
FROM rte_frames AS r
LEFT JOIN frame_labels AS l USING (sequence, frame);
