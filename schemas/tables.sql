-- adaptune results database (results/adaptune.duckdb): tables. Built by the `rte` stage
-- (pipeline.database.store); docs/design.md ("Formats") gives the layout. `study` names the SMBO output a
-- row comes from ('trials' = per-sequence SMBO, 'fixed' = joint SMBO), so that the two studies'
-- trial numbers never collide.

CREATE TABLE schema_info (
    name VARCHAR PRIMARY KEY,       -- 'schema_version' or the .sql file that was applied
    version VARCHAR NOT NULL
);
INSERT INTO schema_info VALUES ('schema_version', '1.1'), ('tables.sql', '1.1');

CREATE TABLE sequences (
    sequence VARCHAR PRIMARY KEY,   -- file stem of data/sequences/<sequence>.mcap
    path VARCHAR NOT NULL,
    frames INTEGER NOT NULL,
    sensor VARCHAR,
    source VARCHAR,
    split VARCHAR,                  -- 'train' | 'validation' | ... from index.json; NULL if unlisted
    labels JSON                     -- [[first_frame, last_frame, label], ...]
);

CREATE TABLE frame_labels (         -- environment label per frame, where known
    sequence VARCHAR NOT NULL,
    frame INTEGER NOT NULL,
    label VARCHAR NOT NULL,
    PRIMARY KEY (sequence, frame)
);

CREATE TABLE ground_truth (         -- T_world_lidar per frame, row-major 3x4; dist_m = path length
    sequence VARCHAR NOT NULL,
    frame INTEGER NOT NULL,
    stamp_ns BIGINT NOT NULL,
    dist_m DOUBLE NOT NULL,
    T_00 DOUBLE, T_01 DOUBLE, T_02 DOUBLE, T_03 DOUBLE, T_10 DOUBLE, T_11 DOUBLE, T_12 DOUBLE, T_13 DOUBLE, T_20 DOUBLE, T_21 DOUBLE, T_22 DOUBLE, T_23 DOUBLE,
    PRIMARY KEY (sequence, frame)
);

-- One row per trial. pipeline.database.store appends one `p_<name> DOUBLE` column per
-- parameter (union over all algorithms; NULL where an algorithm lacks it), then the summary
-- columns mean_rte_pct DOUBLE (mean of rte_frames.t_err_pct) and rte_frames INTEGER (their count).
-- For the joint SMBO (sequence = '__joint__') the summary pools the frames of all sequences.
CREATE TABLE trials (
    study VARCHAR NOT NULL,
    algorithm VARCHAR NOT NULL,
    sequence VARCHAR NOT NULL,
    trial INTEGER NOT NULL,
    status VARCHAR NOT NULL,        -- 'ok' | 'failed' | 'pruned' | 'lost'
    error VARCHAR NOT NULL,         -- '' when ok
    objective DOUBLE,               -- the SMBO objective: mean RTE [%] or the failure penalty
    seed BIGINT,
    params_json VARCHAR,            -- JSON object name -> value
    PRIMARY KEY (study, algorithm, sequence, trial)
);

CREATE TABLE rte_frames (           -- per-start-frame RTE (the paper's y_ij); frames with a segment
    study VARCHAR NOT NULL,
    algorithm VARCHAR NOT NULL,
    sequence VARCHAR NOT NULL,
    trial INTEGER NOT NULL,
    frame INTEGER NOT NULL,         -- first frame of the segment
    end_frame INTEGER NOT NULL,     -- first frame whose path distance > dist(frame) + length_m
    length_m DOUBLE NOT NULL,
    t_err_pct DOUBLE NOT NULL,      -- |E.t| / length_m * 100, E = inv(dEst) dGT
    r_err_deg_per_m DOUBLE NOT NULL -- angle(E.R) / length_m in degrees per metre
);

CREATE TABLE rte_kitti (            -- KITTI devkit segments (start every 10 frames, 100..800 m)
    study VARCHAR NOT NULL,
    algorithm VARCHAR NOT NULL,
    sequence VARCHAR NOT NULL,
    trial INTEGER NOT NULL,
    first_frame INTEGER NOT NULL,
    last_frame INTEGER NOT NULL,
    length_m DOUBLE NOT NULL,
    t_err DOUBLE NOT NULL,          -- devkit units: |E.t| / length (fraction; x100 for %)
    r_err DOUBLE NOT NULL           -- devkit units: angle(E.R) / length [rad/m]
);

-- The descriptor and environment tables name a frame; pipeline.database.store adds their value
-- columns from the Parquet files (d0..d<F-1> FLOAT for a descriptor of width F,
-- schemas.arrow.descriptors_schema; e0..e<D-1> FLOAT for the PCA's dimension D).
CREATE TABLE descriptors (          -- from data/descriptors.parquet
    sequence VARCHAR NOT NULL,
    frame INTEGER NOT NULL,
    stamp_ns BIGINT NOT NULL
);

CREATE TABLE environment (          -- from data/environment.parquet: PCA of the descriptors
    sequence VARCHAR NOT NULL,
    frame INTEGER NOT NULL
);
