"""Evaluation runs over the numpy core of :mod:`posecons.metrics`: :mod:`.evaluate` (a model's or saved
predictions → results with provenance, JSON, plots, trajectories), :mod:`.compare` (Table-1 tables)
and :mod:`.commands` (the CLI)."""
