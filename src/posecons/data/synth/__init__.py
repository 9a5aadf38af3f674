"""Synthetic KITTI-like driving data: a numpy ray caster over analytic primitives."""

from .generate import Drive, drive_folder, generate_synth, make_drive

__all__ = ["Drive", "drive_folder", "generate_synth", "make_drive"]
