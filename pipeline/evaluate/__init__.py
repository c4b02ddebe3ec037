"""The evaluation runner: baseline (the defaults) and fixed (the joint study's best) run on the
evaluated sequences, the adaptive run read back, all three scored by the same per-start-frame
RTE and devkit metric, each optionally R more times with its parameters moved (replicas).

``section`` (params ``evaluate``), ``result`` (the result model), ``runs`` (the runs and their
scores), ``replicas`` (the replica factors). Rendering the result is ``pipeline.report``.
"""
