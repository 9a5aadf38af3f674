"""Data layer: KITTI raw / odometry datasets, calibration and split parsing, ground-truth export,
synthetic KITTI-like data and custom video preparation (see docs/data.md)."""
