"""Pose maths: quaternions, snippet ATE (SPEC §10), Sim(3) alignment, the KITTI devkit's t_err / r_err and the
constant-velocity baseline."""

import numpy as np
import pytest

from posecons.data.trajectory_io import read_kitti_poses
from posecons.errors import PoseconsError
from posecons.metrics.pose import (
    apply_sim3,
    constant_velocity_steps,
    global_from_relative,
    invert_rigid,
    odometry_errors,
    pose_metrics,
    quaternion_to_rotation,
    relative_from_global,
    rotation_to_quaternion,
    scale_alignment,
    snippet_errors,
    umeyama,
)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _pose(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _drive(n: int, seed: int = 0) -> np.ndarray:
    """(n, 4, 4) camera → world poses of a car driving forward along a gentle curve, 1 m a frame."""
    rng = np.random.default_rng(seed)
    steps = [_pose(_rotation([0, 1, 0], 0.02 + 0.01 * rng.standard_normal()), [0.01, 0.0, -1.0]) for _ in range(n - 1)]
    return global_from_relative(np.stack(steps))


def test_relative_and_global_round_trip():
    G = _drive(12)
    assert np.allclose(global_from_relative(relative_from_global(G)), G)
    # T_i maps points of camera i into camera i+1: G_{i+1}·T_i = G_i.
    T = relative_from_global(G)
    assert np.allclose(G[1:] @ T, G[:-1])


def test_snippet_ate_zero_for_perfect_and_scaled_predictions():
    gt = relative_from_global(_drive(30))
    assert np.allclose(snippet_errors(gt, gt), 0.0)
    # One arbitrary scale per snippet (here per step, constant within each snippet window) is absorbed.
    for scale in (0.1, 3.7):
        scaled = gt.copy()
        scaled[:, :3, 3] *= scale
        assert np.allclose(snippet_errors(scaled, gt), 0.0, atol=1e-12)


def test_snippet_ate_by_hand():
    """Mutation caught: left- instead of right-multiplication of the steps (acc = step @ acc)."""
    # GT: 1 m along z each step, turning 90° about y, then 90° about x (they do not commute), then straight.
    z = [0, 0, 1]
    R_y, R_x = _rotation([0, 1, 0], np.pi / 2), _rotation([1, 0, 0], np.pi / 2)  # z ↦ x; z ↦ −y
    gt = np.stack([_pose(R_y, z), _pose(R_x, z), _pose(np.eye(3), z), _pose(np.eye(3), z)])
    pred = np.stack([_pose(np.eye(3), z)] * 4)  # straight on: positions (0, 0, k)
    # GT positions t0, t0 + R_y·t1, … + R_y·R_x·t2, …: (0,0,0), (0,0,1), (1,0,1), (1,−1,1), (1,−2,1).
    # s = Σgt·pred / Σpred² = (1 + 2 + 3 + 4) / (1 + 4 + 9 + 16) = 1/3, and the residual
    # Σ‖s·pred − gt‖² = 4/9 + 10/9 + 2 + 46/9 = 26/3.
    errors = snippet_errors(pred, gt)
    assert errors[0] == pytest.approx(np.sqrt(26 / 3) / 5)
    assert len(errors) == 4  # start frames 0 … N−2, shorter snippets at the end
    assert errors[2:] == pytest.approx([0, 0], abs=1e-12)  # the straight end agrees exactly


def test_snippet_ate_on_real_odometry_09(kitti_dir):
    gt_global = read_kitti_poses(kitti_dir / "odometry" / "poses" / "09.txt")
    assert gt_global.shape == (1591, 4, 4)
    gt = relative_from_global(gt_global)
    rng = np.random.default_rng(0)
    noisy = gt.copy()
    noisy[:, :3, 3] += 0.02 * rng.standard_normal((len(gt), 3))
    noisy[:, :3, 3] *= 0.3  # monocular: unknown global scale
    r = pose_metrics(global_from_relative(noisy), gt_global)
    assert r["n_snippets"] == 1590
    assert 0.005 < r["ate_mean"] < 0.05  # noise of 2 cm per step gives ~1–2 cm snippet errors
    exact = pose_metrics(gt_global, gt_global)
    assert exact["ate_mean"] == pytest.approx(0.0, abs=1e-9) and exact["ate_full_rmse"] == pytest.approx(0.0, abs=1e-9)
    assert r["sim3_scale"] == pytest.approx(1 / 0.3, rel=0.05)
    assert r["segment_lengths"] == [100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0] and r["devkit_lengths"]
    # A constant-velocity model with no images scores a comparable snippet ATE, but not on the full trajectory.
    cv = r["const_velocity"]
    assert cv["ate_mean"] < 0.1 and cv["ate_full_rmse"] > 20 * r["ate_full_rmse"]


def test_umeyama_recovers_a_similarity():
    """Mutations caught: no reflection correction (S = I); S from the sign of det(Σ), which is 0 for planar points."""
    R, s, t = _rotation([1, 0, 0], 0.3), 2.5, np.array([1.0, -2.0, 0.5])
    # A drive on flat ground is planar (y = 0): U·Vᵀ of a rank-2 Σ can be a reflection, as it is here
    # with numpy's SVD, and only the correction from det(U)·det(V) makes it the rotation.
    src = _drive(30)[:, :3, 3]
    dst = s * src @ R.T + t
    s_hat, R_hat, t_hat = umeyama(src, dst)
    assert s_hat == pytest.approx(s) and np.allclose(R_hat, R) and np.allclose(t_hat, t)
    poses = np.stack([_pose(np.eye(3), p) for p in src])
    assert np.allclose(apply_sim3(poses, s, R, t)[:, :3, 3], dst)
    # Points ±3 x, ±2 y, ±1 z seen in a mirror z ↦ −z: Σ = s·R·diag(3, 4/3, −1/3), whose U·Vᵀ is R times
    # the mirror. The best rotation is R, giving up the least spread axis: ŝ = s·(3 + 4/3 − 1/3)/(14/3).
    src = np.concatenate([np.diag([3.0, 2.0, 1.0]), -np.diag([3.0, 2.0, 1.0])])
    dst = s * src @ np.diag([1.0, 1.0, -1.0]) @ R.T + t
    s_hat, R_hat, t_hat = umeyama(src, dst)
    assert s_hat == pytest.approx(s * 6 / 7) and np.allclose(R_hat, R) and np.allclose(t_hat, t)


def test_full_metrics_on_a_short_sequence():
    G = _drive(100)  # ~99 m: shorter than KITTI's 100 m segments
    r = pose_metrics(G, G)
    assert r["ate_full_rmse"] == pytest.approx(0.0, abs=1e-9)
    # arccos near 1 turns rounding into ~1e-8 rad: r_err is zero to 1e-6 °/100 m.
    assert r["t_err"] == pytest.approx(0.0, abs=1e-9) and r["r_err"] == pytest.approx(0.0, abs=1e-6)
    assert r["segment_lengths"] == pytest.approx([99.0 * k / 10 for k in range(1, 9)], rel=1e-3)
    assert r["n_segments"] > 100 and not r["devkit_lengths"]


def test_short_path_segments_of_a_known_error():
    # Straight drive, 1 m a frame, 60 frames (59 m → segment lengths 5.9 k m); the prediction is 10 % too long.
    G = _straight(60, 1.0)
    stretched = G.copy()
    stretched[:, :3, 3] *= 1.1
    r = odometry_errors(stretched, G, "6dof")
    # Each segment ends at the first frame beyond L, floor(L) + 1 frames on: error 0.1·(floor(L) + 1) / L.
    expected = [
        0.1 * (np.floor(L) + 1) / L for L in r["segment_lengths"] for first in range(60) if first + np.floor(L) + 1 < 60
    ]
    assert r["n_segments"] == len(expected)
    assert r["t_err"] == pytest.approx(100 * np.mean(expected))
    assert r["r_err"] == pytest.approx(0.0, abs=1e-9)


LENGTHS = (100, 200, 300, 400, 500, 600, 700, 800)


def _straight(n: int, step: float, yaw: float = 0.0) -> np.ndarray:
    """(n, 4, 4) poses driving ``step`` m a frame along the camera's z, turning by ``yaw`` rad a frame."""
    return global_from_relative(np.stack([_pose(_rotation([0, 1, 0], yaw), [0, 0, -step])] * (n - 1)))


def _devkit_reference(pred: np.ndarray, gt: np.ndarray) -> tuple[float, float, int]:
    """t_err (%), r_err (°/100 m) and segment count written loop by loop from the devkit's definition."""
    dist = np.zeros(len(gt))
    for k in range(1, len(gt)):
        dist[k] = dist[k - 1] + np.linalg.norm(gt[k, :3, 3] - gt[k - 1, :3, 3])
    t_errs, r_errs = [], []
    for first in range(0, len(gt), 10):
        for L in LENGTHS:
            beyond = np.nonzero(dist > dist[first] + L)[0]
            if beyond.size == 0:
                continue
            last = beyond[0]
            E = np.linalg.inv(np.linalg.inv(pred[first]) @ pred[last]) @ (np.linalg.inv(gt[first]) @ gt[last])
            t_errs.append(np.linalg.norm(E[:3, 3]) / L)
            r_errs.append(np.arccos(min(max((np.trace(E[:3, :3]) - 1) / 2, -1.0), 1.0)) / L)
    return 100 * np.mean(t_errs), np.mean(r_errs) * 180 / np.pi * 100, len(t_errs)


def test_odometry_errors_of_a_constant_scale_drift():
    """Every metre predicted 2 % long on a 999 m straight drive: each segment ends L + 1 frames on
    (dist > L, strictly), so its error is 0.02·(L + 1)/L, pooled over all segments of all lengths.
    Catches ≥ for > in the segment end, per-length instead of pooled means, first frames not every
    10th, a wrong % factor, and a 7-DoF alignment that does not absorb a uniform scale."""
    gt = _straight(1000, 1.0)
    pred = gt.copy()
    pred[:, :3, 3] *= 1.02
    expected = [0.02 * (L + 1) / L for first in range(0, 1000, 10) for L in LENGTHS if first + L + 1 < 1000]
    r = odometry_errors(pred, gt, "6dof")
    assert r["t_err"] == pytest.approx(100 * np.mean(expected), rel=1e-9)
    assert r["n_segments"] == len(expected) and r["devkit_lengths"]
    assert r["r_err"] == pytest.approx(0.0, abs=1e-9)
    aligned = odometry_errors(pred, gt, "7dof")
    assert aligned["t_err"] == pytest.approx(0.0, abs=1e-9) and aligned["alignment_scale"] == pytest.approx(1 / 1.02)


def test_scale_alignment_is_kitti_odom_evals_positions_only_factor():
    """By hand: GT positions 0, (1, 0, 0), (2, 0, 0), predicted 0, (2, 2, 0), (2, 0, 0) (no rotation):
    s = Σ g·p / Σ p·p = (2 + 4) / (8 + 4) = 0.5 — not Umeyama's Sim(3) scale, which also rotates and
    shifts. The same prediction seen from another world frame (a rigid T_0 on the left) has the same s,
    as that toolbox takes every pose relative to the first. Then a real drive predicted at a quarter of
    its scale: s = 4 and no error left. Caught: s of the world positions (not relative to the first),
    Σ p·p / Σ g·p, the Sim(3) scale, the factor not applied before t_err."""
    gt = np.stack([_pose(np.eye(3), [x, 0, 0]) for x in (0, 1, 2)])
    pred = np.stack([_pose(np.eye(3), t) for t in ([0, 0, 0], [2, 2, 0], [2, 0, 0])])
    assert scale_alignment(pred, gt) == pytest.approx(0.5, rel=1e-12)
    assert umeyama(pred[:, :3, 3], gt[:, :3, 3])[0] != pytest.approx(0.5, rel=1e-3)
    elsewhere = _pose(_rotation([0, 0, 1], 0.5), [5.0, -3.0, 1.0])
    assert scale_alignment(elsewhere @ pred, gt) == pytest.approx(0.5, rel=1e-12)

    gt = _drive(400)
    pred = gt.copy()
    pred[:, :3, 3] *= 0.25
    r = odometry_errors(elsewhere @ pred, gt, "scale")
    assert r["alignment"] == "scale" and r["alignment_scale"] == pytest.approx(4.0, rel=1e-9)
    assert r["t_err"] == pytest.approx(0.0, abs=1e-9) and odometry_errors(pred, gt, "6dof")["t_err"] > 30


def test_odometry_errors_of_a_pure_yaw_bias():
    """GT drives 0.9 m a frame straight; the prediction also turns 1e-4 rad a frame. A segment of
    length L spans n = floor(L/0.9) + 1 frames, so its rotation error is n·1e-4/L; r_err is their mean
    in °/100 m. Catches a wrong °/100 m factor and per-length instead of pooled means."""
    gt, pred = _straight(1000, 0.9), _straight(1000, 0.9, yaw=1e-4)
    spans = {L: int(np.floor(L / 0.9)) + 1 for L in LENGTHS}
    expected = [spans[L] * 1e-4 / L for first in range(0, 1000, 10) for L in LENGTHS if first + spans[L] < 1000]
    r = odometry_errors(pred, gt, "6dof")
    assert r["r_err"] == pytest.approx(np.degrees(np.mean(expected)) * 100, rel=1e-9)
    assert r["n_segments"] == len(expected)


@pytest.mark.parametrize("sequence", ["04", "09"])
def test_odometry_errors_equal_the_devkit_definition_on_kitti(kitti_dir, sequence):
    """Real KITTI GT against a copy that drifts in scale and heading, with noise, 0.3× the scale: equal to
    the loop-by-loop reference to 1e-6 after SE(3) and after Sim(3) alignment (SE(3) is skipped in the
    code: it changes no relative motion). Catches SE(3) and Sim(3) swapped, a missing clamp of the angle (NaN on GT against itself) and any
    slip in the segment bookkeeping on a real, curving, irregularly sampled path."""
    gt = read_kitti_poses(kitti_dir / "odometry" / "poses" / f"{sequence}.txt")
    rng = np.random.default_rng(0)
    steps = relative_from_global(gt)
    steps[:, :3, 3] *= 0.3 * (1 + 1e-4 * np.arange(len(steps)))[:, None]
    steps[:, :3, 3] += 0.01 * rng.standard_normal((len(steps), 3))
    steps = steps @ _pose(_rotation([0, 1, 0], 2e-4), [0, 0, 0])
    pred = global_from_relative(steps)
    for alignment, with_scale in (("6dof", False), ("7dof", True)):
        r = odometry_errors(pred, gt, alignment)
        moved = apply_sim3(pred, *umeyama(pred[:, :3, 3], gt[:, :3, 3], with_scale))
        t_err, r_err, n = _devkit_reference(moved, gt)
        assert (r["t_err"], r["r_err"], r["n_segments"]) == (
            pytest.approx(t_err, abs=1e-6),
            pytest.approx(r_err, abs=1e-6),
            n,
        )
        assert r["t_err"] > 1 and r["r_err"] > 0.1  # a real error, not two zeros
    exact = odometry_errors(gt, gt, "6dof")
    assert exact["t_err"] == pytest.approx(0.0, abs=1e-9) and exact["r_err"] == pytest.approx(0.0, abs=1e-6)


def test_constant_velocity_steps():
    gt = relative_from_global(_drive(6))
    assert np.allclose(constant_velocity_steps(gt, "first"), gt[0])
    prev = constant_velocity_steps(gt, "previous")
    assert np.allclose(prev[0], gt[0]) and np.allclose(prev[1:], gt[:-1])


def test_count_mismatch():
    G = _drive(10)
    with pytest.raises(PoseconsError, match="9 predicted poses but 10 ground-truth poses"):
        pose_metrics(G[:-1], G)
    assert np.allclose(invert_rigid(G) @ G, np.eye(4))


def test_quaternion_convention_and_round_trip():
    # 90° about z: q = (0, 0, sin 45°, cos 45°) in (x, y, z, w) order.
    Rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert np.allclose(rotation_to_quaternion(Rz[None]), [[0, 0, np.sqrt(0.5), np.sqrt(0.5)]])
    # Includes 180° rotations, where w = 0 and the trace-based formula alone would divide by zero.
    random = quaternion_to_rotation(np.random.default_rng(0).standard_normal((200, 4)))
    R = np.concatenate([random, np.diag([1.0, -1, -1])[None], np.diag([-1.0, -1, 1])[None]])
    assert np.allclose(quaternion_to_rotation(rotation_to_quaternion(R)), R, atol=1e-12)
