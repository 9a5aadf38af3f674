"""Core maths of evaluation, in numpy (as evo's ``core``): no file formats, no plots, no CLI.

:mod:`.depth` — Eigen depth metrics, the KITTI protocol (Garg crop, median scaling), scale
statistics (σ/μ, per-frame scales, drift); :mod:`.pose` — rigid-transform helpers and quaternions,
Umeyama Sim(3) alignment, snippet ATE, full ATE, the KITTI devkit's t_err / r_err and the
constant-velocity baseline;
:mod:`.stats` — a study's spread over seeds, paired differences, exact sign-flip tests, Holm, MDE.
Readers and writers of the files they work on live in :mod:`posecons.data`, figures in
:mod:`posecons.plots`.
"""
