"""Sim-to-real comparison: real KITTI slices against simulated KITTI along the same poses
(docs/design.md, "The sim-to-real comparison").

``compare.run_realism`` is the entry: it reads real slices (``slices``), simulates the same
frames, and compares scan statistics (``statistics``) and the frame-to-frame registration error
of odometry adapters at their defaults (``registration``); ``report`` writes the table (JSON,
markdown) and the figure (PNG).
"""
