"""The one suite runner: settings (baseline, fixed, adaptive, ...) over a suite of subjects
(simulated worlds or recorded runs), each on replicas, scored by the per-start-frame RTE; and
the statistics every suite summary uses (``statistics``)."""
