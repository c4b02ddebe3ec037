"""Evaluation of baseline, fixed and adaptive parameters, and the report (figures, markdown)."""
