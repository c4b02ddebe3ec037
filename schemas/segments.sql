-- Error of every segment, for pipeline.database.store (schema version 1.0).
-- Inputs (temporary tables): seg_starts(sequence, frame, length_m): the segment starts;
-- est(study, algorithm, sequence, trial, frame, T_00 .. T_23): the estimated trajectories;
-- and the table ground_truth. Output: study, algorithm, sequence, trial, frame, end_frame,
-- length_m, t_err = |E.t| / length (fraction), r_err = angle(E.R) / length [rad/m].
-- The segment ends at the first frame whose path distance is strictly greater than
-- dist(frame) + length (the KITTI devkit rule), found by an ASOF join; frames that share a
-- path distance (standstill) are collapsed to the first of them first, so the ASOF match is
-- exactly that first frame. dGT = inv(GT_i) GT_j, dEst = inv(Est_i) Est_j (rigid inverses),
-- E = inv(dEst) dGT.
WITH dist_first AS (
    SELECT sequence, dist_m, min(frame) AS frame
    FROM ground_truth
    GROUP BY sequence, dist_m
),
targets AS (
    SELECT s.sequence, s.frame, s.length_m, g.dist_m + s.length_m AS target_m
    FROM seg_starts AS s
    JOIN ground_truth AS g USING (sequence, frame)
),
ends AS (
    SELECT t.sequence, t.frame, t.length_m, d.frame AS end_frame
    FROM targets AS t
    ASOF JOIN dist_first AS d ON t.sequence = d.sequence AND d.dist_m > t.target_m
),
poses AS (
    SELECT study, algorithm, sequence, trial, frame, COLUMNS('^T_[0-2][0-3]$') FROM est
    UNION ALL
    SELECT '' AS study, '' AS algorithm, sequence, -1 AS trial, frame,
           COLUMNS('^T_[0-2][0-3]$')
    FROM ground_truth
),
rel AS (  -- inv(P_i) P_j of every segment of every trajectory (trial -1: the ground truth)
    SELECT a.study, a.algorithm, a.sequence, a.trial, n.frame, n.end_frame, n.length_m,
           a.T_00 * b.T_00 + a.T_10 * b.T_10 + a.T_20 * b.T_20 AS r00,
           a.T_00 * b.T_01 + a.T_10 * b.T_11 + a.T_20 * b.T_21 AS r01,
           a.T_00 * b.T_02 + a.T_10 * b.T_12 + a.T_20 * b.T_22 AS r02,
           a.T_01 * b.T_00 + a.T_11 * b.T_10 + a.T_21 * b.T_20 AS r10,
           a.T_01 * b.T_01 + a.T_11 * b.T_11 + a.T_21 * b.T_21 AS r11,
           a.T_01 * b.T_02 + a.T_11 * b.T_12 + a.T_21 * b.T_22 AS r12,
           a.T_02 * b.T_00 + a.T_12 * b.T_10 + a.T_22 * b.T_20 AS r20,
           a.T_02 * b.T_01 + a.T_12 * b.T_11 + a.T_22 * b.T_21 AS r21,
           a.T_02 * b.T_02 + a.T_12 * b.T_12 + a.T_22 * b.T_22 AS r22,
           a.T_00 * (b.T_03 - a.T_03) + a.T_10 * (b.T_13 - a.T_13) + a.T_20 * (b.T_23 - a.T_23) AS t0,
           a.T_01 * (b.T_03 - a.T_03) + a.T_11 * (b.T_13 - a.T_13) + a.T_21 * (b.T_23 - a.T_23) AS t1,
           a.T_02 * (b.T_03 - a.T_03) + a.T_12 * (b.T_13 - a.T_13) + a.T_22 * (b.T_23 - a.T_23) AS t2
    FROM ends AS n
    JOIN poses AS a ON a.sequence = n.sequence AND a.frame = n.frame
    JOIN poses AS b ON b.study = a.study AND b.algorithm = a.algorithm
        AND b.sequence = a.sequence AND b.trial = a.trial AND b.frame = n.end_frame
),
err AS (
    SELECT e.study, e.algorithm, e.sequence, e.trial, e.frame, e.end_frame, e.length_m,
           e.r00 * (g.t0 - e.t0) + e.r10 * (g.t1 - e.t1) + e.r20 * (g.t2 - e.t2) AS et0,
           e.r01 * (g.t0 - e.t0) + e.r11 * (g.t1 - e.t1) + e.r21 * (g.t2 - e.t2) AS et1,
           e.r02 * (g.t0 - e.t0) + e.r12 * (g.t1 - e.t1) + e.r22 * (g.t2 - e.t2) AS et2,
           0.5 * (e.r00 * g.r00 + e.r01 * g.r01 + e.r02 * g.r02 + e.r10 * g.r10 + e.r11 * g.r11 + e.r12 * g.r12 + e.r20 * g.r20 + e.r21 * g.r21 + e.r22 * g.r22 - 1.0) AS cos_angle
    FROM rel AS e
    JOIN rel AS g ON g.trial = -1 AND g.sequence = e.sequence
        AND g.frame = e.frame AND g.length_m = e.length_m
    WHERE e.trial <> -1
)
SELECT study, algorithm, sequence, trial, frame, end_frame, length_m,
       sqrt(et0 * et0 + et1 * et1 + et2 * et2) / length_m AS t_err,
       acos(greatest(-1.0, least(1.0, cos_angle))) / length_m AS r_err
FROM err
