"""The paper's KITTI protocol (Table II) as a preset of params values (``preset``)."""
