"""Evaluation runs over the numpy core of :mod:`posecons.metrics`: :mod:`.evaluate` (a model's or saved
predictions → results with provenance, JSON, plots, trajectories) and :mod:`.compare` (Table-1
tables); their commands are in :mod:`posecons.cli.evaluation`."""
