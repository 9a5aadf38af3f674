"""End-to-end: `posecons evaluate-depth`, `evaluate-pose` and `compare` on small files written here."""

import io
import json
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from posecons.cli import main
from posecons.data.trajectory_io import read_kitti_poses, read_tum, write_kitti_poses

DRIVE = "2011_09_26/2011_09_26_drive_0002_sync"
DEPTH_KEYS = {
    "abs_rel",
    "sq_rel",
    "rmse",
    "rmse_log",
    "a1",
    "a2",
    "a3",
    "scaling",
    "scales",
    "scale_cv",
    "scale_cv_pooled",
    "scale_std_over_median",
    "per_sequence",
    "n_frames",
    "n_skipped",
    "skipped",
}
POSE_KEYS = {"ate_mean", "ate_std", "n_snippets", "ate_full_rmse", "t_err", "r_err", "alignment", "const_velocity"}


def _write_gt(path, maps, lines):
    arrays = {f"{i:06d}": m.astype(np.float32) for i, m in enumerate(maps)}
    np.savez(path, lines=np.array(lines, dtype=np.str_), **arrays)


@pytest.fixture
def depth_files(tmp_path):
    """Three frames over two sequences and two GT sizes; the last frame has no valid GT."""
    rng = np.random.default_rng(0)
    maps = [rng.uniform(5, 60, (40, 124)), rng.uniform(5, 60, (37, 122)), np.zeros((40, 124))]
    lines = [f"{DRIVE} 0000000001 l", "2011_09_26/2011_09_26_drive_0009_sync 0000000005 l", f"{DRIVE} 0000000002 l"]
    _write_gt(tmp_path / "gt.npz", maps, lines)
    np.save(tmp_path / "pred.npy", rng.uniform(0.02, 0.5, (3, 16, 48)).astype(np.float32))
    return tmp_path


def test_evaluate_depth_from_predictions(depth_files, capsys):
    out = depth_files
    rc = main(
        [
            "evaluate-depth",
            "--pred-disps",
            str(out / "pred.npy"),
            "--gt",
            str(out / "gt.npz"),
            "--json",
            str(out / "depth.json"),
            "--plots",
            str(out / "plots"),
        ]
    )
    assert rc == 0
    result = json.loads((out / "depth.json").read_text())
    assert DEPTH_KEYS <= set(result)
    assert (result["n_frames"], result["n_skipped"], result["skipped"]) == (2, 1, [2])
    assert result["skipped_lines"] == [f"{DRIVE} 2 l"] and result["scales"][2] is None
    assert set(result["per_sequence"]) == {DRIVE, "2011_09_26/2011_09_26_drive_0009_sync"}
    assert result["per_sequence"][DRIVE]["n"] == 1
    printed = capsys.readouterr().out
    assert "| σ/μ | Abs Rel |" in printed and f"{result['abs_rel']:.3f}" in printed
    for name in ("scale_boxplot.png", "scale_over_time.png", "abs_rel_histogram.png"):
        assert (out / "plots" / name).stat().st_size > 1000


def test_evaluate_depth_bad_input_names_the_file(depth_files, capsys):
    out = depth_files
    np.save(out / "short.npy", np.full((2, 16, 48), 0.1, np.float32))
    assert main(["evaluate-depth", "--pred-disps", str(out / "short.npy"), "--gt", str(out / "gt.npz")]) == 2
    assert "short.npy has 2 frames but" in capsys.readouterr().err
    nan = np.full((3, 16, 48), 0.1, np.float32)
    nan[1, 0, 0] = np.nan
    np.save(out / "nan.npy", nan)
    assert main(["evaluate-depth", "--pred-disps", str(out / "nan.npy"), "--gt", str(out / "gt.npz")]) == 2
    assert "nan.npy: 1 NaN/inf or non-positive" in capsys.readouterr().err

    # As many lines as the ground truth, but another frame: checked by content, not by count.
    def with_split(name: str, lines: str) -> int:
        (out / name).write_text(lines)
        args = ["--pred-disps", str(out / "pred.npy"), "--gt", str(out / "gt.npz"), "--split-file", str(out / name)]
        return main(["evaluate-depth", *args])

    assert with_split("other.txt", f"{DRIVE} 1 l\n2011_09_26/2011_09_26_drive_0009_sync 6 l\n{DRIVE} 2 l\n") == 2
    err = capsys.readouterr().err
    assert "other.txt:2: '2011_09_26/2011_09_26_drive_0009_sync 6 l' does not match" in err and "gt.npz" in err
    # The padding of the frame number does not matter.
    assert (
        with_split("same.txt", f"{DRIVE} 0000000001 l\n2011_09_26/2011_09_26_drive_0009_sync 5 l\n{DRIVE} 2 l\n") == 0
    )


def _write_monodepth2_gt(path, maps):
    """As Monodepth2's export_gt_depth.py: ``np.savez_compressed(path, data=np.array(gt_depths))`` of float32
    maps. The numpy 1 it ran on made maps of several sizes an object array without being asked, pickled
    (protocol 3) under numpy 1's module name numpy.core.multiarray."""
    maps = [m.astype(np.float32) for m in maps]
    if len({m.shape for m in maps}) == 1:
        np.savez_compressed(path, data=np.array(maps))
        return
    data, npy = np.array(maps, dtype=object), io.BytesIO()
    np.lib.format.write_array_header_1_0(npy, np.lib.format.header_data_from_array_1_0(data))
    pickle.dump(data, npy, protocol=3)
    payload = npy.getvalue().replace(b"cnumpy._core.multiarray\n", b"cnumpy.core.multiarray\n")
    assert b"cnumpy.core.multiarray\n_reconstruct" in payload
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("data.npy", payload)


@pytest.mark.parametrize("sizes", ["several sizes", "one size"])
def test_evaluate_depth_reads_monodepth2s_gt_depths_with_the_split_file(depth_files, capsys, sizes):
    """The same maps as Monodepth2 saves them score as they do from export-gt's file. Caught: the file
    refused (the old "not a posecons ground-truth file"), the maps out of order, the split file's length
    not checked against it, the file read without its lines, an object that is no array unpickled."""
    out = depth_files
    with np.load(out / "gt.npz") as data:
        lines = [str(s) for s in data["lines"]]
        maps = [data[f"{i:06d}"] for i in range(len(lines))]
    if sizes == "one size":
        maps = [m[:37, :122] for m in maps]
        _write_gt(out / "gt.npz", maps, lines)
    _write_monodepth2_gt(out / "md2.npz", maps)
    (out / "test_files.txt").write_text("".join(line + "\n" for line in lines))
    base = ["evaluate-depth", "--pred-disps", str(out / "pred.npy")]
    assert main([*base, "--gt", str(out / "gt.npz"), "--json", str(out / "own.json")]) == 0
    md2 = [*base, "--gt", str(out / "md2.npz"), "--split-file", str(out / "test_files.txt")]
    assert main([*md2, "--json", str(out / "md2.json")]) == 0
    own, theirs = (json.loads((out / f"{n}.json").read_text()) for n in ("own", "md2"))
    assert theirs["per_frame_abs_rel"] == own["per_frame_abs_rel"] and theirs["abs_rel"] == own["abs_rel"]
    assert theirs["per_sequence"] == own["per_sequence"]

    def refused(argv: list[str], message: str) -> None:
        capsys.readouterr()
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err, err

    refused(
        [*base, "--gt", str(out / "md2.npz")], "md2.npz: Monodepth2's ground truth names no frames; pass --split-file"
    )
    (out / "short.txt").write_text("".join(line + "\n" for line in lines[:2]))
    refused([*base, "--gt", str(out / "md2.npz"), "--split-file", str(out / "short.txt")], "short.txt has 2 lines but")
    np.savez_compressed(out / "evil.npz", data=np.array([maps[0], Path("x")], dtype=object))
    refused([*base, "--gt", str(out / "evil.npz"), "--split-file", str(out / "test_files.txt")], "refused to unpickle")


def test_evaluate_depth_with_a_fixed_scale_factor(tmp_path, capsys):
    """GT 10 m everywhere, disparity 0.54 (1.85 m): --scaling none --scale-factor 2.7 predicts 5 m, abs rel
    exactly 0.5. Catches the factor not applied (abs rel 0.81) or not passed on from the command line."""
    _write_gt(tmp_path / "gt.npz", [np.full((40, 124), 10.0)] * 2, [f"{DRIVE} 1 l", f"{DRIVE} 2 l"])
    np.save(tmp_path / "pred.npy", np.full((2, 16, 48), 0.54, np.float32))
    argv = ["evaluate-depth", "--pred-disps", str(tmp_path / "pred.npy"), "--gt", str(tmp_path / "gt.npz")]
    assert main([*argv, "--scaling", "none", "--scale-factor", "2.7", "--json", str(tmp_path / "d.json")]) == 0
    result = json.loads((tmp_path / "d.json").read_text())
    assert result["abs_rel"] == pytest.approx(0.5, rel=1e-6) and result["scale_factor"] == 2.7
    assert "scaling none × 2.7" in capsys.readouterr().out  # bad values: tests/test_bad_inputs.py


def test_evaluate_depth_dense_has_no_crop_and_the_users_depth_range(tmp_path, capsys):
    """One 10 × 20 frame, no scaling, --gt-kind dense --min-depth 0.1 --max-depth 10. Rows 0–3 (above the
    Garg crop): GT 2 m, prediction 4 m (error 1, 80 pixels). Rows 4–9: column 0 invalid (GT 0), column 1
    GT 12 m beyond the range, column 2 GT 9 m predicted 20 m and clamped to 10 m (error 1/9, 6 pixels),
    the rest exact (102 pixels). abs rel = (80 + 6/9) / 188. Caught: the Garg crop kept (rows 0–3 and 9,
    column 19 dropped), the range not masking column 1, the clamp at 80 m (error 11/9), invalid pixels kept."""
    gt, pred = np.full((10, 20), 2.0), np.full((10, 20), 2.0)
    pred[:4] = 4.0
    gt[4:, 0], gt[4:, 1], gt[4:, 2], pred[4:, 2] = 0.0, 12.0, 9.0, 20.0
    _write_gt(tmp_path / "gt.npz", [gt], ["custom/custom_drive_0000_sync 0 l"])
    np.save(tmp_path / "pred.npy", (1 / pred)[None].astype(np.float32))
    argv = ["evaluate-depth", "--pred-disps", str(tmp_path / "pred.npy"), "--gt", str(tmp_path / "gt.npz")]
    argv += ["--gt-kind", "dense", "--min-depth", "0.1", "--max-depth", "10", "--scaling", "none"]
    assert main([*argv, "--json", str(tmp_path / "d.json")]) == 0
    result = json.loads((tmp_path / "d.json").read_text())
    assert result["abs_rel"] == pytest.approx((80 + 6 / 9) / 188, rel=1e-6)
    assert (result["gt_kind"], result["crop"], result["depth_range"]) == ("dense", "none", [0.1, 10.0])
    assert "depth range 0.1–10 m" in capsys.readouterr().out


def test_evaluate_depth_dense_prediction_at_twice_the_depth_scores_zero(tmp_path):
    """Two frames of random dense GT with 30 % invalid pixels (0) whose prediction is junk; elsewhere the
    prediction is 2 × GT (frame 0) and 4 × GT (frame 1): per-frame median scaling gives abs rel 0, scales
    0.5 and 0.25 and σ/μ = 0.125 / 0.375. Caught: invalid pixels evaluated, the scale taken over all pixels."""
    rng = np.random.default_rng(0)
    gts = [rng.uniform(0.5, 5.0, (24, 32)) for _ in range(2)]
    for gt in gts:
        gt[rng.random(gt.shape) < 0.3] = 0.0
    preds = [np.where(gt > 0, factor * gt, rng.uniform(0.2, 50, gt.shape)) for gt, factor in zip(gts, (2, 4))]
    _write_gt(tmp_path / "gt.npz", gts, [f"custom/custom_drive_0000_sync {i} l" for i in range(2)])
    np.save(tmp_path / "pred.npy", 1 / np.stack(preds).astype(np.float32))
    argv = ["evaluate-depth", "--pred-disps", str(tmp_path / "pred.npy"), "--gt", str(tmp_path / "gt.npz")]
    assert main([*argv, "--gt-kind", "dense", "--max-depth", "10", "--json", str(tmp_path / "d.json")]) == 0
    result = json.loads((tmp_path / "d.json").read_text())
    assert result["abs_rel"] == pytest.approx(0.0, abs=1e-6) and result["a1"] == 1.0
    assert result["scales"] == pytest.approx([0.5, 0.25], rel=1e-6)
    assert result["scale_cv"] == pytest.approx(1 / 3, rel=1e-6)


def test_evaluate_depth_eigen_to_benchmark(tmp_path, capsys):
    """Predictions for the 697 Eigen test frames, each a constant depth 1 + i/10 m (i: its Eigen index);
    improved GT on the 652 eigen_benchmark lines holding the depth of their Eigen frame. Picking the
    right frames gives abs rel 0, any other pick does not; the GT kind becomes improved (no crop).
    Catches predictions taken in benchmark order without the look-up, and a LiDAR protocol."""
    from posecons.data.splits import read_split

    eigen = [str(line) for line in read_split("eigen")]
    bench = [str(line) for line in read_split("eigen_benchmark")]
    depths = 1 + np.arange(len(eigen)) / 10
    maps = [np.full((8, 16), depths[eigen.index(line)]) for line in bench]
    _write_gt(tmp_path / "gt.npz", maps, bench)
    np.save(tmp_path / "pred.npy", (1 / depths[:, None, None] * np.ones((1, 4, 8))).astype(np.float32))
    argv = ["evaluate-depth", "--pred-disps", str(tmp_path / "pred.npy"), "--gt", str(tmp_path / "gt.npz")]
    assert main([*argv, "--eigen-to-benchmark", "--scaling", "none", "--json", str(tmp_path / "d.json")]) == 0
    result = json.loads((tmp_path / "d.json").read_text())
    assert result["n_frames"] == 652 and result["abs_rel"] == pytest.approx(0.0, abs=1e-6)
    assert result["gt_kind"] == "improved" and result["crop"] == "none" and result["eigen_to_benchmark"]
    capsys.readouterr()
    np.save(tmp_path / "short.npy", np.ones((696, 4, 8), np.float32))
    short = ["evaluate-depth", "--pred-disps", str(tmp_path / "short.npy"), "--gt", str(tmp_path / "gt.npz")]
    assert main([*short, "--eigen-to-benchmark"]) == 2
    assert "short.npy has 696 frames, not the 697 of the Eigen test split" in capsys.readouterr().err


@pytest.fixture
def pose_files(tmp_path, kitti_dir):
    """The first 120 poses of odometry 09 and a noisy prediction at another scale."""
    gt = read_kitti_poses(kitti_dir / "odometry" / "poses" / "09.txt")[:120]
    pred = gt.copy()
    pred[:, :3, 3] = 0.5 * pred[:, :3, 3] + np.random.default_rng(0).normal(0, 0.05, (120, 3))
    write_kitti_poses(tmp_path / "gt.txt", gt)
    write_kitti_poses(tmp_path / "pred.txt", pred)
    return tmp_path


def test_evaluate_pose_from_a_trajectory_file(pose_files, kitti_dir):
    out = pose_files
    rc = main(
        [
            "evaluate-pose",
            "--pred-poses",
            str(out / "pred.txt"),
            "--gt-poses",
            str(out / "gt.txt"),
            "--json",
            str(out / "pose.json"),
            "--out-dir",
            str(out / "traj"),
        ]
    )
    assert rc == 0
    result = json.loads((out / "pose.json").read_text())
    assert POSE_KEYS <= set(result) and POSE_KEYS - {"const_velocity"} <= set(result["const_velocity"])
    assert result["n_snippets"] == 119 and result["sim3_scale"] == pytest.approx(2.0, rel=0.05)
    times, written = read_tum(out / "traj" / "trajectory_tum.txt")
    assert np.allclose(times, np.arange(120) / 10)
    assert np.allclose(written, read_kitti_poses(out / "traj" / "trajectory_kitti.txt"), atol=1e-6)
    assert (out / "traj" / "trajectory.png").stat().st_size > 1000


@pytest.mark.parametrize("align", ["7dof", "6dof", "scale"])
def test_evaluate_pose_aligns_as_asked_for_t_err(tmp_path, kitti_dir, capsys, align):
    """All of odometry 09 predicted exactly but at half the scale: Sim(3) and the positions-only scale make
    t_err zero, SE(3) leaves half of each segment's chord as error (t_err under 50 %). Catches --align not
    reaching the metrics or the print."""
    gt_file = kitti_dir / "odometry" / "poses" / "09.txt"
    pred = read_kitti_poses(gt_file)
    pred[:, :3, 3] *= 0.5
    write_kitti_poses(tmp_path / "pred.txt", pred)
    argv = ["evaluate-pose", "--pred-poses", str(tmp_path / "pred.txt"), "--gt-poses", str(gt_file)]
    assert main([*argv, "--align", align, "--json", str(tmp_path / "pose.json")]) == 0
    result = json.loads((tmp_path / "pose.json").read_text())
    assert result["alignment"] == result["const_velocity"]["alignment"] == align
    if align != "6dof":
        assert result["t_err"] == pytest.approx(0.0, abs=1e-4) and result["r_err"] == pytest.approx(0.0, abs=1e-4)
    else:
        assert 30 < result["t_err"] < 50 and result["r_err"] == pytest.approx(0.0, abs=1e-4)
    out = capsys.readouterr().out
    assert (
        f"t_err / r_err: {align} alignment, {result['n_segments']} segments of 100–800 m (the devkit's lengths)" in out
    )


def test_evaluate_pose_scores_the_first_frames_of_a_shorter_prediction(tmp_path, kitti_dir, capsys):
    """A noisy prediction of the first 900 of odometry 09's 1591 frames scores as it does against those 900
    GT poses — kitti-odom-eval's segments, those with both ends among the predicted frames — and the output
    says so. Caught: the prediction refused (the old behaviour), scored against the whole GT, or silently."""
    gt = read_kitti_poses(kitti_dir / "odometry" / "poses" / "09.txt")
    pred = gt[:900].copy()
    pred[:, :3, 3] = 0.5 * pred[:, :3, 3] + np.random.default_rng(0).normal(0, 0.3, (900, 3))
    write_kitti_poses(tmp_path / "pred.txt", pred)
    write_kitti_poses(tmp_path / "gt_900.txt", gt[:900])
    argv = ["evaluate-pose", "--pred-poses", str(tmp_path / "pred.txt"), "--times", str(tmp_path / "times.txt")]
    (tmp_path / "times.txt").write_text("".join(f"{i / 10:.6e}\n" for i in range(len(gt))))
    gt_file = str(kitti_dir / "odometry" / "poses" / "09.txt")
    argv_full = [*argv, "--gt-poses", gt_file, "--out-dir", str(tmp_path / "t")]
    assert main([*argv_full, "--json", str(tmp_path / "short.json")]) == 0
    assert f"scoring the first 900 of the 1591 poses of {gt_file}: " in capsys.readouterr().out
    (tmp_path / "times.txt").write_text("".join(f"{i / 10:.6e}\n" for i in range(900)))
    assert main([*argv, "--gt-poses", str(tmp_path / "gt_900.txt"), "--json", str(tmp_path / "cut.json")]) == 0
    assert "scoring the first" not in capsys.readouterr().out
    short, cut = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("short", "cut"))
    assert (short["n_frames"], short["n_gt_poses"], cut["n_gt_poses"]) == (900, 1591, 900)
    assert short["n_segments"] > 0 and short["t_err"] > 0.1
    for key in ("t_err", "r_err", "n_segments", "ate_mean", "ate_full_rmse", "segment_lengths"):
        assert short[key] == cut[key], key
    assert short["const_velocity"] == cut["const_velocity"]
    assert len(read_tum(tmp_path / "t" / "gt_tum.txt")[0]) == 900


def test_evaluate_pose_bad_input(pose_files, capsys):
    out = pose_files
    lines = (out / "pred.txt").read_text().splitlines()
    (out / "long.txt").write_text("\n".join(lines + lines[-1:]) + "\n")
    assert main(["evaluate-pose", "--pred-poses", str(out / "long.txt"), "--gt-poses", str(out / "gt.txt")]) == 2
    assert "long.txt has 121 poses but" in capsys.readouterr().err
    (out / "cols.txt").write_text("\n".join(lines[:5] + [lines[5] + " 1.0"] + lines[6:]) + "\n")
    assert main(["evaluate-pose", "--pred-poses", str(out / "cols.txt"), "--gt-poses", str(out / "gt.txt")]) == 2
    assert "cols.txt:6: expected 12 numbers" in capsys.readouterr().err


def test_compare_bolds_the_best(tmp_path, capsys):
    base = {
        "scale_cv": 0.08,
        "abs_rel": 0.115,
        "sq_rel": 0.9,
        "rmse": 4.8,
        "rmse_log": 0.19,
        "a1": 0.877,
        "a2": 0.959,
        "a3": 0.981,
    }
    better = dict(base, scale_cv=0.05, abs_rel=0.112, a1=0.880)
    (tmp_path / "base.json").write_text(json.dumps(base))
    (tmp_path / "run" / "eval").mkdir(parents=True)
    (tmp_path / "run" / "eval" / "depth.json").write_text(json.dumps(better))
    rc = main(["compare", str(tmp_path / "base.json"), str(tmp_path / "run"), "--out", str(tmp_path / "t.md")])
    assert rc == 0
    table = (tmp_path / "t.md").read_text().splitlines()
    assert table[0].startswith("| Method | σ/μ | Abs Rel | Sq Rel | RMSE | RMSE log | δ<1.25")
    assert table[2] == "| base | 0.080 | 0.115 | **0.900** | **4.800** | **0.190** | 0.877 | **0.959** | **0.981** |"
    assert table[3] == (
        "| run | **0.050** | **0.112** | **0.900** | **4.800** | **0.190** | **0.880** | **0.959** | **0.981** |"
    )
    assert capsys.readouterr().out.splitlines() == table
    assert main(["compare", str(tmp_path / "base.json"), "--names", "a", "b"]) == 2


def test_evaluate_depth_plots_the_best_median_and_worst_frame_beside_its_ground_truth(tmp_path, monkeypatch):
    """Four dense frames whose predictions are 2 × GT with relative noise 0.3, 0, 0.2 and 0.1: with
    --data-path, examples.png shows frames 1 (best), 2 (the median of the ranking 1, 3, 2, 0) and 0
    (worst), each with its own image and GT and the prediction times its frame scale. Caught: picks in
    split order, the unscaled prediction, another frame's image."""
    from posecons.evaluation import evaluate

    rng = np.random.default_rng(0)
    folder = tmp_path / "data" / "custom" / "custom_drive_0000_sync" / "image_02" / "data"
    folder.mkdir(parents=True)
    gts, disps, images = [], [], []
    for i, noise in enumerate((0.3, 0.0, 0.2, 0.1)):
        gt = rng.uniform(1.0, 5.0, (24, 32))
        gts.append(gt)
        disps.append(1 / (2 * gt * (1 + noise * rng.choice([-1.0, 1.0], gt.shape))))
        images.append(rng.integers(0, 256, (24, 32, 3), dtype=np.uint8))
        Image.fromarray(images[-1]).save(folder / f"{i:010d}.png")
    _write_gt(tmp_path / "gt.npz", gts, [f"custom/custom_drive_0000_sync {i} l" for i in range(4)])
    np.save(tmp_path / "pred.npy", np.stack(disps).astype(np.float32))
    shown = []
    plot = evaluate.plot_depth_examples
    monkeypatch.setattr(evaluate, "plot_depth_examples", lambda rows, path: shown.extend(rows) or plot(rows, path))
    argv = ["evaluate-depth", "--pred-disps", str(tmp_path / "pred.npy"), "--gt", str(tmp_path / "gt.npz")]
    argv += ["--gt-kind", "dense", "--max-depth", "10", "--data-path", str(tmp_path / "data")]
    assert main([*argv, "--plots", str(tmp_path / "plots")]) == 0
    assert [row["title"].split(":")[0] for row in shown] == [f"custom/custom_drive_0000_sync {i} l" for i in (1, 2, 0)]
    for row, i in zip(shown, (1, 2, 0)):
        pred = 1 / np.float32(disps[i]).astype(np.float64)
        np.testing.assert_array_equal(row["image"], images[i])
        np.testing.assert_allclose(row["gt"], gts[i], rtol=1e-6)
        np.testing.assert_allclose(row["pred"], pred * np.median(gts[i]) / np.median(pred), rtol=1e-5)
    assert (tmp_path / "plots" / "examples.png").stat().st_size > 1000
