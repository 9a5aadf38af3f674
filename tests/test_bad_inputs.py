"""The bad-input catalogue: every command, given a bad file, number, path, checkpoint or video, exits
with status 2 and one message naming the file or option, prints no traceback, changes nothing the
user had (the input trees are hashed before and after) and leaves no output behind.

Interrupts (exit 128 + signal, last.pt saved) are in test_training_interrupts.py.
"""

from __future__ import annotations

import hashlib
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from PIL import Image

from posecons.checkpoint import save_checkpoint
from posecons.cli import main
from posecons.config import load_config
from posecons.data.splits import read_split
from posecons.model import PoseConsModel
from rgbd_sequence import write_sequence

TINY = ["model.height=64", "model.width=96", "model.num_layers=10", "model.pretrained=false"]
TRAIN = "train --config kitti/baseline --data-path {syn} --out {out} --quiet " + " ".join(
    f"--set {s}" for s in TINY + ["data.split=synth", "train.batch_size=2", "data.num_workers=0", "train.max_steps=1"]
)
DRIVE = "2020_01_01/2020_01_01_drive_0000_sync"
RGBD = "prepare-rgbd --input {in}/rgbd --out {out} --color frame-*.color.png --fx 20 --fy 20 --cx 8 --cy 6"
STUDY_SPEC = {
    "preset": "synth/demo",
    "data": {"synth": {"drives": 3, "frames": 16, "width": 128, "height": 64, "neighbours": 3, "seed": 0}},
    "seeds": [0],
    "variants": {"a": []},
}
STUDY_SPECS = {  # spec file name → what differs from STUDY_SPEC
    "study_unknown_key": {"variantz": {}},
    "study_no_seeds": {"seeds": []},
    "study_no_variants": {"variants": {}},
    "study_bad_variant": {"variants": {"a": [], "b": ["loss.constraints=[xyz]"]}},
    "study_bad_synth": {"data": {"synth": {**STUDY_SPEC["data"]["synth"], "drives": 1}}},
    "study_two_data": {"data": {**STUDY_SPEC["data"], "path": "/data/kitti_raw"}},
    "study_bad_profile": {"data": {"synth": {**STUDY_SPEC["data"]["synth"], "profile": "city"}}},
}


def _hash(*roots: Path) -> str:
    """Names, modes and bytes of every file and folder under ``roots``."""
    digest = hashlib.sha256()
    for root in roots:
        for path in sorted(root.rglob("*")):
            digest.update(f"{path.relative_to(root)} {path.stat().st_mode}".encode())
            if path.is_file():
                digest.update(path.read_bytes())
    return digest.hexdigest()


@pytest.fixture(scope="module")
def world(make_synth, tmp_path_factory) -> dict[str, Path]:
    """A user's files: a small synthetic dataset, a checkpoint, and one bad file of each kind."""
    syn = make_synth(2, 10, 96, 32, 4)
    inp = tmp_path_factory.mktemp("inputs")
    config = load_config(overrides=TINY)
    save_checkpoint(inp / "model.pt", {"config": config.to_dict(), "model": PoseConsModel(config).state_dict()})
    rng = np.random.default_rng(0)
    (inp / "random.pt").write_bytes(rng.bytes(3000))
    (inp / "empty.pt").write_bytes(b"")
    (inp / "garbage.mp4").write_bytes(rng.bytes(4096))
    (inp / "random.npy").write_bytes(rng.bytes(500))
    (inp / "empty.png").write_bytes(b"")
    (inp / "blocker").write_text("a regular file where a folder would have to be")
    (inp / "userdir").mkdir()
    (inp / "userdir" / "notes.txt").write_text("the user's notes")
    (inp / "userdir" / "depth").mkdir()
    (inp / "userdir" / "depth" / "keep.txt").write_text("also the user's")
    (inp / "two_fields.txt").write_text(f"{DRIVE} 1\n")
    (inp / "frames").mkdir()
    Image.new("RGB", (96, 32)).save(inp / "frames" / "000000.png")
    # calibration and pose files with one NaN
    nan_raw = inp / "nan_raw" / "2020_01_01"
    nan_raw.mkdir(parents=True)
    calib = (syn / "2020_01_01" / "calib_cam_to_cam.txt").read_text().splitlines()
    calib = [line.replace(line.split()[1], "nan", 1) if line.startswith("P_rect_02") else line for line in calib]
    (nan_raw / "calib_cam_to_cam.txt").write_text("\n".join(calib) + "\n")
    (inp / "nan_calib.txt").write_text("K: 100 0 50 0 nan 20 0 0 1\n")
    gt_poses = syn / "odometry" / "poses" / "01.txt"
    rows = gt_poses.read_text().splitlines()
    (inp / "nan_poses.txt").write_text("\n".join([rows[0].rsplit(" ", 1)[0] + " nan"] + rows[1:]) + "\n")
    (inp / "two_poses.txt").write_text("\n".join(rows[:2]) + "\n")
    (inp / "two_times.txt").write_text("0\n0.1\n")
    (inp / "static.txt").write_text("2011_09_26 drive_0001 not-a-frame\n")
    (inp / "result.json").write_text('{"abs_rel": 0.1}')
    shutil.copytree(syn, inp / "no_oxts", ignore=shutil.ignore_patterns("oxts"))  # as `prepare` writes a video
    # an RGB-D sequence (3 frames, 16 × 12) and broken files beside it, picked by each case's patterns
    rgbd = inp / "rgbd"
    write_sequence(rgbd)
    for i in range(3):
        Image.fromarray(np.ones((6, 8), np.uint16)).save(rgbd / f"small-{i:06d}.png")
        for name, matrix in {
            "nan": np.full((4, 4), np.nan),
            "scaled": np.diag([2.0, 2, 2, 1]),
            "row": np.ones((4, 4)),
        }.items():
            np.savetxt(rgbd / f"{name}-{i:06d}.txt", matrix if i == 1 else np.eye(4))
    for i in range(2):  # no gone-000002.png
        shutil.copyfile(rgbd / f"frame-{i:06d}.depth.png", rgbd / f"gone-{i:06d}.png")
    (inp / "tum.txt").write_text("10 0 0 0 0 0 0 1\n11 0 0 0 0 0 0 1\n")
    (inp / "two_rows_k.txt").write_text("585 0 320\n0 585 240\n")
    for name, change in STUDY_SPECS.items():
        (inp / f"{name}.yaml").write_text(yaml.safe_dump({**STUDY_SPEC, **change}))
    assert (
        main(
            [
                "export-gt",
                "--data-path",
                str(syn),
                "--split-file",
                str(syn / "splits/synth/test_files.txt"),
                "--out",
                str(inp / "gt.npz"),
            ]
        )
        == 0
    )
    # training data with damaged frames (copies of the synthetic set)
    zero = inp / "zero_syn"
    shutil.copytree(syn, zero)
    for image in (zero / DRIVE).glob("image_0*/data/*.png"):
        image.write_bytes(b"")
    odd = inp / "odd_syn"
    shutil.copytree(syn, odd)
    lines = read_split(syn / "splits/synth/train_files.txt")
    for side, camera in (("l", "image_02"), ("r", "image_03")):  # all but each camera's reference frame
        reference = next((f"{line.frame:010d}.png" for line in lines if line.side == side), None)
        for image in (odd / DRIVE / camera / "data").glob("*.png"):
            if image.name != reference:
                Image.new("RGB", (100, 32)).save(image)
    return {"syn": syn, "in": inp}


# (id, command line, fragments the message must hold); {syn}: dataset, {in}: user files, {out}: output path
CASES = [
    # synth
    ("synth-out-under-file", "synth --out {in}/blocker/data", ["--out", "blocker is a file"]),
    (
        "synth-out-foreign-folder",
        "synth --out {in}/userdir --drives 2 --frames 5 --width 32 --height 16",
        ["userdir", "posecons did not write"],
    ),
    ("synth-drives-0", "synth --out {out} --drives 0", ["--drives", "≥ 1"]),
    ("synth-profile", "synth --out {out} --profile city", ["--profile", "invalid choice: 'city'"]),
    ("synth-one-drive", "synth --out {out} --drives 1 --frames 5 --width 32 --height 16", ["at least 2 drives"]),
    ("synth-frames-word", "synth --out {out} --frames many", ["--frames", "expected an integer"]),
    ("synth-width-0", "synth --out {out} --width 0", ["--width", "≥ 1"]),
    # export-gt
    (
        "export-gt-split-two-fields",
        "export-gt --data-path {in}/nan_raw --split-file {in}/two_fields.txt --out {out}",
        ["two_fields.txt:1", "fields"],
    ),
    (
        "export-gt-nan-in-calibration",
        "export-gt --data-path {in}/nan_raw --split-file {syn}/splits/synth/test_files.txt --out {out}",
        ["calib_cam_to_cam.txt", "P_rect_02", "NaN"],
    ),
    (
        "export-gt-missing-split",
        "export-gt --data-path {syn} --split-file {in}/nope.txt --out {out}",
        ["nope.txt: split file not found"],
    ),
    (
        "export-gt-out-is-folder",
        "export-gt --data-path {syn} --split-file {syn}/splits/synth/test_files.txt --out {in}/userdir",
        ["--out", "userdir", "is a folder"],
    ),
    # prepare
    (
        "prepare-missing-input",
        "prepare --input {in}/nope.mp4 --out {out} --fx 1 --fy 1 --cx 1 --cy 1",
        ["nope.mp4: input not found"],
    ),
    (
        "prepare-garbage-video",
        "prepare --input {in}/garbage.mp4 --out {out} --fx 1 --fy 1 --cx 1 --cy 1",
        ["garbage.mp4", "video"],
    ),
    ("prepare-fx-only", "prepare --input {in}/frames --out {out} --fx 100", ["--fx --fy --cx --cy: give all four"]),
    ("prepare-fov-180", "prepare --input {in}/frames --out {out} --fov 180", ["--fov", "1–170"]),
    ("prepare-fx-nan", "prepare --input {in}/frames --out {out} --fx nan --fy 1 --cx 1 --cy 1", ["--fx", "> 0"]),
    (
        "prepare-calib-nan",
        "prepare --input {in}/frames --out {out} --calib {in}/nan_calib.txt",
        ["nan_calib.txt:1", "NaN"],
    ),
    (
        "prepare-both-intrinsics",
        "prepare --input {in}/frames --out {out} --calib {in}/nan_calib.txt --fx 1 --fy 1 --cx 1 --cy 1",
        ["not --fx --fy --cx --cy and --calib"],
    ),
    (
        "prepare-out-under-file",
        "prepare --input {in}/frames --out {in}/blocker/x --fx 1 --fy 1 --cx 1 --cy 1",
        ["--out", "blocker is a file"],
    ),
    # prepare-rgbd
    (
        "prepare-rgbd-depth-of-another-size",
        RGBD + " --depth small-*.png --depth-scale 1000",
        ["small-000000.png: depth image is 8×6 pixels", "frame-000000.color.png is 16×12"],
    ),
    (
        "prepare-rgbd-missing-depth",
        RGBD + " --depth gone-*.png --depth-scale 1000",
        ["gone-000002.png: depth image of frame-000002.color.png not found"],
    ),
    (
        "prepare-rgbd-missing-pose",
        RGBD + " --depth frame-*.depth.png --depth-scale 1000 --poses gone-*.txt",
        ["gone-000000.txt: pose file of frame-000000.color.png not found"],
    ),
    (
        "prepare-rgbd-nan-in-a-pose",
        RGBD + " --depth frame-*.depth.png --depth-scale 1000 --poses nan-*.txt",
        ["nan-000001.txt", "NaN"],
    ),
    (
        "prepare-rgbd-scaled-rotation",
        RGBD + " --depth frame-*.depth.png --depth-scale 1000 --poses scaled-*.txt",
        ["scaled-000001.txt", "rotation is not orthonormal"],
    ),
    (
        "prepare-rgbd-bottom-row",
        RGBD + " --depth frame-*.depth.png --depth-scale 1000 --poses row-*.txt",
        ["row-000001.txt", "bottom row 1 1 1 1 is not 0 0 0 1"],
    ),
    (
        "prepare-rgbd-no-tum-pose-at-a-frame",
        RGBD + " --depth frame-*.depth.png --depth-scale 1000 --tum-poses {in}/tum.txt",
        ["tum.txt: no pose at the time of", "frame-000000.color.png"],
    ),
    ("prepare-rgbd-depth-scale-0", RGBD + " --depth frame-*.depth.png --depth-scale 0", ["--depth-scale", "> 0"]),
    ("prepare-rgbd-depth-scale-nan", RGBD + " --depth frame-*.depth.png --depth-scale nan", ["--depth-scale", "> 0"]),
    (
        "prepare-rgbd-depth-scale-word",
        RGBD + " --depth frame-*.depth.png --depth-scale mm",
        ["--depth-scale", "expected a number"],
    ),
    (
        "prepare-rgbd-pattern-without-star",
        RGBD.replace("frame-*.color.png", "frame.png") + " --depth frame-*.depth.png --depth-scale 1000",
        ["--color 'frame.png'", "exactly one *"],
    ),
    (
        "prepare-rgbd-no-intrinsics",
        RGBD.replace(" --fx 20 --fy 20 --cx 8 --cy 6", "") + " --depth frame-*.depth.png --depth-scale 1000",
        ["--fx --fy --cx --cy (pixels) or --calib FILE"],
    ),
    (
        "prepare-rgbd-intrinsics-two-rows",
        RGBD.replace(" --fx 20 --fy 20 --cx 8 --cy 6", " --calib {in}/two_rows_k.txt")
        + " --depth frame-*.depth.png --depth-scale 1000",
        ["two_rows_k.txt", "3 × 3 intrinsics matrix"],
    ),
    (
        "prepare-rgbd-test-from-past-the-end",
        RGBD + " --depth frame-*.depth.png --depth-scale 1000 --test-from 3 --gap 0",
        ["frame-*.color.png", "only 0 test frames", "--test-from 3 --gap 0 of 3 frames", "at least 3"],
    ),
    (
        "prepare-rgbd-gap-eats-training",
        RGBD + " --depth frame-*.depth.png --depth-scale 1000 --test-from 0",
        ["only 0 training frames", "--test-from 0 --gap 20"],
    ),
    (
        "prepare-rgbd-gap-negative",
        RGBD + " --depth frame-*.depth.png --depth-scale 1000 --test-from 1 --gap -1",
        ["--gap", "-1"],
    ),
    (
        "prepare-rgbd-out-under-file",
        RGBD.replace("{out}", "{in}/blocker/x") + " --depth frame-*.depth.png --depth-scale 1000",
        ["--out", "blocker is a file"],
    ),
    # cache
    (
        "cache-default-split-wrong-data",
        "cache --data-path {syn} --config kitti/baseline --out {out}",
        ["eigen_zhou/train_files.txt:1", "missing"],
    ),
    (
        "cache-out-foreign-folder",
        "cache --data-path {syn} --config kitti/baseline --set data.split=synth --out {in}/userdir",
        ["userdir", "holds no frame cache"],
    ),
    # build-split
    (
        "build-split-val-fraction",
        "build-split --data-path {syn} --out {out} --val-fraction 2",
        ["--val-fraction", "[0, 1]"],
    ),
    ("build-split-no-frames", "build-split --data-path {in}/userdir --out {out}", ["userdir", "no usable frames"]),
    (
        "build-split-bad-static",
        "build-split --data-path {syn} --out {out} --static-frames {in}/static.txt",
        ["static.txt:1"],
    ),
    # train
    ("train-batch-negative", TRAIN + " --set train.batch_size=-2", ["train.batch_size must be ≥ 1, got -2"]),
    ("train-batch-zero", TRAIN + " --set train.batch_size=0", ["train.batch_size must be ≥ 1, got 0"]),
    ("train-lr-nan", TRAIN + " --set train.lr=nan", ["train.lr must be a finite number"]),
    ("train-workers-negative", TRAIN + " --set data.num_workers=-1", ["data.num_workers must be ≥ 0"]),
    ("train-val-every-word", TRAIN + " --set train.val_every=weekly", ["train.val_every", '"off"']),
    ("train-unknown-key", TRAIN + " --set train.bach_size=2", ["unknown config key 'train.bach_size'"]),
    ("train-unknown-preset", TRAIN.replace("kitti/baseline", "kitti/nope"), ["'kitti/nope'", "bundled preset"]),
    ("train-missing-data", TRAIN.replace("--data-path {syn}", "--data-path {in}/nope"), ["nope", "not a directory"]),
    (
        "train-velocity-without-oxts",
        TRAIN.replace("--data-path {syn}", "--data-path {in}/no_oxts") + " --set loss.velocity_weight=0.05",
        ["no_oxts/2020_01_01", "oxts/data", "OXTS packet not found", "loss.velocity_weight"],
    ),
    ("train-resume-without-run", TRAIN + " --resume", ["last.pt does not exist"]),
    ("train-batch-too-large", TRAIN + " --set train.batch_size=64", ["fewer than one batch", "train.batch_size"]),
    (
        "train-bundled-split-wrong-data",
        TRAIN + " --set data.split=eigen_zhou",
        ["eigen_zhou/train_files.txt:1", "missing"],
    ),
    (
        "train-zero-byte-image-in-worker",
        TRAIN.replace("{syn}", "{in}/zero_syn") + " --set data.num_workers=1",
        ["unreadable image", ".png"],
    ),
    ("train-frame-of-other-size", TRAIN.replace("{syn}", "{in}/odd_syn"), ["100×32 pixels", "same drive"]),
    ("train-cache-dir-not-a-cache", TRAIN + " --set data.cache_dir={in}/userdir", ["userdir", "not a frame cache"]),
    ("train-devices-0", TRAIN + " --devices 0", ["--devices", "≥ 1"]),
    ("train-max-steps-negative", TRAIN + " --max-steps -1", ["--max-steps", "≥ 0"]),
    ("train-out-under-file", TRAIN.replace("--out {out}", "--out {in}/blocker/run"), ["--out", "blocker is a file"]),
    # import-monodepth2
    ("import-monodepth2-no-folder", "import-monodepth2 {in}/nope --out {out}/m.pt", ["nope", "not a Monodepth2 model"]),
    ("import-monodepth2-no-encoder", "import-monodepth2 {in}/userdir --out {out}/m.pt", ["encoder.pth is missing"]),
    # demo
    ("demo-out-under-file", "demo --out {in}/blocker/demo", ["--out", "blocker is a file"]),
    ("demo-seed-negative", "demo --out {out} --seed -1", ["--seed", "≥ 0"]),
    # evaluate-depth
    (
        "evaluate-depth-batch-0",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz --batch-size 0",
        ["--batch-size", "≥ 1"],
    ),
    (
        "evaluate-depth-json-under-file",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz --json {in}/blocker/d.json",
        ["--json", "blocker is a file"],
    ),
    ("evaluate-depth-no-gt", "evaluate-depth --pred-disps {in}/random.npy", ["--pred-disps needs --gt"]),
    (
        "evaluate-depth-scale-factor-with-median-scaling",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz --scale-factor 5.4",
        ["--scale-factor needs --scaling none"],
    ),
    (
        "evaluate-depth-scale-factor-0",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz --scaling none --scale-factor 0",
        ["--scale-factor", "> 0"],
    ),
    (
        "evaluate-depth-eigen-to-benchmark-lidar",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz --eigen-to-benchmark --gt-kind lidar",
        ["--eigen-to-benchmark", "not --gt-kind lidar"],
    ),
    (
        "evaluate-depth-eigen-to-benchmark-checkpoint",
        "evaluate-depth --checkpoint {in}/model.pt --data-path {syn} "
        "--split-file {syn}/splits/synth/test_files.txt --gt {in}/gt.npz --eigen-to-benchmark",
        ["--eigen-to-benchmark", "--pred-disps"],
    ),
    (
        "evaluate-depth-random-npy",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz",
        ["random.npy", "not a .npy array of numbers"],
    ),
    (
        "evaluate-depth-gt-not-npz",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/result.json",
        ["result.json", "ground-truth"],
    ),
    (
        "evaluate-depth-random-checkpoint",
        "evaluate-depth --checkpoint {in}/random.pt --data-path {syn} "
        "--split-file {syn}/splits/synth/test_files.txt --gt {in}/gt.npz",
        ["random.pt", "not a readable checkpoint"],
    ),
    (
        "evaluate-depth-empty-checkpoint",
        "evaluate-depth --checkpoint {in}/empty.pt --data-path {syn} "
        "--split-file {syn}/splits/synth/test_files.txt --gt {in}/gt.npz",
        ["empty.pt", "not a readable checkpoint"],
    ),
    (
        "evaluate-depth-device-foo",
        "evaluate-depth --checkpoint {in}/model.pt --data-path {syn} "
        "--split-file {syn}/splits/synth/test_files.txt --gt {in}/gt.npz --device foo",
        ["--device", "'foo'"],
    ),
    (
        "evaluate-depth-checkpoint-needs-data",
        "evaluate-depth --checkpoint {in}/model.pt --gt {in}/gt.npz",
        ["--checkpoint needs --data-path"],
    ),
    (
        "evaluate-depth-dense-without-max-depth",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz --gt-kind dense",
        ["--gt-kind dense needs --max-depth"],
    ),
    (
        "evaluate-depth-dense-without-gt",
        "evaluate-depth --checkpoint {in}/model.pt --data-path {syn} "
        "--split-file {syn}/splits/synth/test_files.txt --gt-kind dense --max-depth 10",
        ["--gt-kind dense needs --gt"],
    ),
    (
        "evaluate-depth-min-depth-above-max-depth",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz --min-depth 20 --max-depth 10",
        ["--min-depth 20 must be below --max-depth 10"],
    ),
    (
        "evaluate-depth-max-depth-0",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz --max-depth 0",
        ["--max-depth", "> 0"],
    ),
    (
        "evaluate-depth-eigen-to-benchmark-dense",
        "evaluate-depth --pred-disps {in}/random.npy --gt {in}/gt.npz --eigen-to-benchmark --gt-kind dense",
        ["--eigen-to-benchmark", "not --gt-kind dense"],
    ),
    # evaluate-pose
    (
        "evaluate-pose-sequence-word",
        "evaluate-pose --checkpoint {in}/model.pt --gt-poses {in}/two_poses.txt "
        "--data-path {syn}/odometry --sequence abc",
        ["--sequence", "expected an integer", "'abc'"],
    ),
    (
        "evaluate-pose-nan-poses",
        "evaluate-pose --pred-poses {in}/two_poses.txt --gt-poses {in}/nan_poses.txt",
        ["nan_poses.txt:1", "NaN"],
    ),
    (
        "evaluate-pose-align-unknown",
        "evaluate-pose --pred-poses {in}/two_poses.txt --gt-poses {in}/two_poses.txt --align 5dof",
        ["--align", "'5dof'"],
    ),
    (
        "evaluate-pose-longer-than-gt",  # a shorter prediction is scored on its frames; a longer one is refused
        "evaluate-pose --pred-poses {syn}/odometry/poses/01.txt --gt-poses {in}/two_poses.txt",
        ["01.txt has", "two_poses.txt has 2"],
    ),
    (
        "evaluate-pose-times-mismatch",
        "evaluate-pose --pred-poses {syn}/odometry/poses/01.txt "
        "--gt-poses {syn}/odometry/poses/01.txt --times {in}/two_times.txt",
        ["two_times.txt has 2 timestamps"],
    ),
    (
        "evaluate-pose-out-dir-is-file",
        "evaluate-pose --pred-poses {in}/two_poses.txt --gt-poses {in}/two_poses.txt --out-dir {in}/blocker",
        ["--out-dir", "blocker: exists and is not a folder"],
    ),
    # compare
    ("compare-missing", "compare {in}/nope.json", ["nope.json: no such evaluation JSON"]),
    ("compare-not-depth", "compare {in}/result.json", ["result.json: not a depth evaluation"]),
    ("compare-out-under-file", "compare {in}/result.json --out {in}/blocker/t.md", ["--out", "blocker is a file"]),
    # study
    ("study-spec-missing", "study --spec {in}/nope.yaml --out {out}", ["nope.yaml", "neither a file nor a bundled"]),
    (
        "study-spec-unknown-key",
        "study --spec {in}/study_unknown_key.yaml --out {out}",
        ["study_unknown_key.yaml: unknown key 'variantz'"],
    ),
    (
        "study-spec-no-seeds",
        "study --spec {in}/study_no_seeds.yaml --out {out}",
        ["study_no_seeds.yaml: seeds must be a non-empty"],
    ),
    (
        "study-spec-no-variants",
        "study --spec {in}/study_no_variants.yaml --out {out}",
        ["study_no_variants.yaml: variants must be a non-empty"],
    ),
    (
        "study-spec-bad-variant-config",
        "study --spec {in}/study_bad_variant.yaml --out {out}",
        ["study_bad_variant.yaml: variant 'b'", "loss.constraints: unknown ['xyz']"],
    ),
    (
        "study-spec-bad-synth",
        "study --spec {in}/study_bad_synth.yaml --out {out}",
        ["study_bad_synth.yaml", "at least 2 drives"],
    ),
    (
        "study-spec-bad-profile",
        "study --spec {in}/study_bad_profile.yaml --out {out}",
        ["study_bad_profile.yaml", "unknown --profile 'city'; known: street, open"],
    ),
    (
        "study-spec-two-data",
        "study --spec {in}/study_two_data.yaml --out {out}",
        ["study_two_data.yaml: data: give one of"],
    ),
    ("study-kitti-without-data", "study --spec study/kitti_gpu --out {out}", ["kitti_gpu.yaml", "--data-path"]),
    (
        "study-out-under-file",
        "study --spec {in}/study_no_seeds.yaml --out {in}/blocker/s",
        ["--out", "blocker is a file"],
    ),
    ("study-report-only-nothing", "study --report-only --report {out}/r.md", ["--report-only needs --results"]),
    (
        "study-report-only-not-a-study",
        "study --report-only --results {in}/userdir --report {out}/r.md",
        ["userdir: no study.json"],
    ),
    # predict
    (
        "predict-out-foreign-folder",
        "predict --checkpoint {in}/model.pt --input {in}/frames --out {in}/userdir --quiet",
        ["userdir", "posecons did not write"],
    ),
    (
        "predict-out-under-file",
        "predict --checkpoint {in}/model.pt --input {in}/frames --out {in}/blocker/p",
        ["--out", "blocker is a file"],
    ),
    (
        "predict-batch-0",
        "predict --checkpoint {in}/model.pt --input {in}/frames --out {out} --batch-size 0",
        ["--batch-size", "≥ 1"],
    ),
    (
        "predict-zero-byte-image",
        "predict --checkpoint {in}/model.pt --input {in}/empty.png --out {out} --quiet",
        ["empty.png", "unreadable image"],
    ),
    (
        "predict-garbage-video",
        "predict --checkpoint {in}/model.pt --input {in}/garbage.mp4 --out {out} --quiet",
        ["garbage.mp4", "video"],
    ),
    (
        "predict-random-checkpoint",
        "predict --checkpoint {in}/random.pt --input {in}/frames --out {out} --quiet",
        ["random.pt", "not a readable checkpoint"],
    ),
    (
        "predict-intrinsics-nan",
        "predict --checkpoint {in}/model.pt --input {in}/frames --out {out} --quiet --intrinsics nan,1,2,3",
        ["--intrinsics", "NaN"],
    ),
    (
        "predict-device-foo",
        "predict --checkpoint {in}/model.pt --input {in}/frames --out {out} --device foo",
        ["--device", "'foo'"],
    ),
    (
        "predict-scale-0",
        "predict --checkpoint {in}/model.pt --input {in}/frames --out {out} --scale 0",
        ["--scale", "> 0"],
    ),
    # export
    ("export-random-checkpoint", "export --checkpoint {in}/random.pt --out {out}", ["random.pt", "not a readable"]),
    ("export-out-under-file", "export --checkpoint {in}/model.pt --out {in}/blocker/e", ["--out", "blocker is a file"]),
    (
        "export-tolerance-negative",
        "export --checkpoint {in}/model.pt --out {out} --tolerance -1",
        ["--tolerance", "≥ 0"],
    ),
]
if not torch.cuda.is_available():
    CASES.append(
        (
            "evaluate-depth-device-cuda",
            "evaluate-depth --checkpoint {in}/model.pt --data-path {syn} "
            "--split-file {syn}/splits/synth/test_files.txt --gt {in}/gt.npz --device cuda",
            ["--device cuda", "CUDA is not available"],
        )
    )


@pytest.mark.parametrize("command,fragments", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_one_clear_line_and_changes_nothing(world, tmp_path, capsys, command, fragments):
    argv = [a.format(syn=world["syn"], out=tmp_path / "out", **{"in": world["in"]}) for a in shlex.split(command)]
    before = _hash(world["syn"], world["in"])
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: a usage error
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and "DataLoader worker" not in err, err
    message = err.strip().splitlines()[-1]
    assert message.startswith(f"posecons {argv[0]}: error: "), err
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in {message!r}"
    assert _hash(world["syn"], world["in"]) == before, "the user's files changed"
    assert list(tmp_path.iterdir()) == [], "a failed command left output behind"


def test_the_catalogue_covers_every_command():
    from posecons.cli import build_parser

    commands = set(build_parser()._subparsers._group_actions[0].choices)
    assert commands == {c[1].split()[0] for c in CASES} and len(CASES) >= 40


def test_predict_again_into_its_output_keeps_the_users_files(world, tmp_path):
    """A second predict into the same folder replaces its own outputs only (the bug: rmtree of OUT/depth)."""
    out = tmp_path / "pred"
    args = [
        "predict",
        "--checkpoint",
        str(world["in"] / "model.pt"),
        "--input",
        str(world["in"] / "frames"),
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(args) == 0
    (out / "depth" / "notes.txt").write_text("the user's")
    (out / "mine.txt").write_text("also the user's")
    assert main(args + ["--no-trajectory"]) == 0
    assert (out / "depth" / "notes.txt").read_text() == "the user's" and (out / "mine.txt").exists()
    assert (out / "depth" / "000000.npy").is_file() and not (out / "trajectory_kitti.txt").exists()
