"""Rendering: the evaluate stage's metrics JSON, plot data, report.md and figures, the KITTI
Table II layout, and what every reporting stage writes with (``outputs``). The runs themselves
are ``pipeline.evaluate``."""
