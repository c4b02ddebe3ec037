"""Simulated worlds and LiDAR sensors: the toy worlds (cave, open, street, composite), simulated
KITTI along the real trajectories, ray casting, the sensor models (docs/design.md, "Layout")."""
