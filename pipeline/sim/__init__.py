"""Simulated worlds and LiDAR sensors: the toy worlds (cave, open, street, composite), simulated
KITTI along the real trajectories, ray casting, the sensor models (docs/design.md, "Layout")."""

GENERATOR_VERSION = 2
"""The world generator's version: raise it with any change that makes a seed give another world
or other scans (worlds, routes, sensors, ray casting, noise). The verdict's suites are frozen
with it (params ``verdict.world_generator``) and refuse to run on another one."""
