"""Studies: variants × seeds of a training preset → runs → evaluation → a results report with paired
differences (``posecons study``; docs/study.md)."""
