"""Synthetic KITTI-like driving data: a numpy ray caster over analytic primitives."""

from .generate import Drive, check_synth_args, drive_folder, generate_synth, make_drive

__all__ = ["Drive", "check_synth_args", "drive_folder", "generate_synth", "make_drive"]
