"""SMBO tuning: hyperopt TPE ask/tell over an adapter's ParameterSpace, trials run through an
Executor (process pool or Dask), results in the trials table (docs/design.md, "Formats").

Entry point: ``run_trials(sequence_paths, out_dir, TrialsSection(...), seed, joint=False)``.
"""
