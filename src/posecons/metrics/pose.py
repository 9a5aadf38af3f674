"""Ego-motion maths: rigid transforms and quaternions in numpy, Umeyama alignment, the standard
5-frame snippet ATE (SPEC §10), the full-trajectory ATE and the KITTI odometry devkit's t_err / r_err.

Conventions: global poses G are camera → world (KITTI pose files); the relative pose of step i is
T_i = T_{i+1←i} = inv(G_{i+1}) · G_i, the same transform the pose net returns for the ordered pair
(I_i, I_{i+1}). All poses are (..., 4, 4) float64 numpy arrays.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import PoseconsError

SNIPPET_LENGTH = 5  # frames per snippet in the published protocol (4 relative poses)
KITTI_SEGMENT_LENGTHS = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)  # metres, the odometry devkit's
KITTI_FIRST_FRAME_STEP = 10  # the devkit starts a segment at every 10th frame (one a second at 10 Hz)
ALIGNMENTS = ("7dof", "6dof", "scale")  # of the prediction to GT before t_err / r_err, as kitti-odom-eval names them
CONST_VELOCITY_MODES = ("first", "previous")


def invert_rigid(T: np.ndarray) -> np.ndarray:
    """Inverse [Rᵀ | −Rᵀt] of rigid transforms (..., 4, 4)."""
    R_t = np.swapaxes(T[..., :3, :3], -1, -2)
    inv = np.zeros_like(T)
    inv[..., :3, :3] = R_t
    inv[..., :3, 3] = -(R_t @ T[..., :3, 3:4])[..., 0]
    inv[..., 3, 3] = 1.0
    return inv


def relative_from_global(G: np.ndarray) -> np.ndarray:
    """(N, 4, 4) camera → world poses → (N−1, 4, 4) steps T_i = inv(G_{i+1}) · G_i."""
    return invert_rigid(G[1:]) @ G[:-1]


def global_from_relative(T: np.ndarray) -> np.ndarray:
    """(N−1, 4, 4) steps T_{i+1←i} → (N, 4, 4) camera → world poses with G_0 = I (G_{i+1} = G_i · inv(T_i))."""
    G = np.empty((len(T) + 1, 4, 4))
    G[0] = np.eye(4)
    for i, step in enumerate(invert_rigid(T)):
        G[i + 1] = G[i] @ step
    return G


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations → (N, 4) unit quaternions (x, y, z, w) with w ≥ 0.

    Builds each quaternion from its largest component, which keeps the division well conditioned.
    """
    R = np.asarray(R, dtype=np.float64)
    trace = np.trace(R, axis1=1, axis2=2)
    # 4·q_k² for k = x, y, z, w; the largest is used as the pivot.
    sq = np.stack([1 + 2 * R[:, 0, 0] - trace, 1 + 2 * R[:, 1, 1] - trace, 1 + 2 * R[:, 2, 2] - trace, 1 + trace], 1)
    # Off-diagonal sums/differences: 4·q_i·q_j for the pairs (x,y), (x,z), (y,z), (w,x), (w,y), (w,z).
    xy, xz, yz = R[:, 0, 1] + R[:, 1, 0], R[:, 0, 2] + R[:, 2, 0], R[:, 1, 2] + R[:, 2, 1]
    wx, wy, wz = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
    products = np.stack(
        [  # row k: 4·q_k·(x, y, z, w)
            np.stack([sq[:, 0], xy, xz, wx], 1),
            np.stack([xy, sq[:, 1], yz, wy], 1),
            np.stack([xz, yz, sq[:, 2], wz], 1),
            np.stack([wx, wy, wz, sq[:, 3]], 1),
        ],
        1,
    )
    pivot = np.argmax(sq, axis=1)
    q = products[np.arange(len(R)), pivot]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q * np.where(q[:, 3:] < 0, -1.0, 1.0)


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (x, y, z, w), normalised here → (N, 3, 3) rotations."""
    x, y, z, w = (np.asarray(q, dtype=np.float64) / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], 1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], 1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], 1),
        ],
        1,
    )


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """Rotation angle in radians of rotation matrices (..., 3, 3)."""
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(cos, -1.0, 1.0))


def snippet_positions(steps: np.ndarray) -> np.ndarray:
    """(K, 4, 4) steps → (K+1, 3) translation columns of the running products I, T_0, T_0·T_1, …

    Right multiplication, as in the published protocol (kept for comparability, although the
    geometrically consistent chain would multiply the inverses).
    """
    positions = [np.zeros(3)]
    acc = np.eye(4)
    for step in steps:
        acc = acc @ step
        positions.append(acc[:3, 3].copy())
    return np.stack(positions)


def snippet_errors(pred_steps: np.ndarray, gt_steps: np.ndarray, length: int = SNIPPET_LENGTH) -> np.ndarray:
    """Snippet ATE for every start frame i = 0 … N−2 over (N−1, 4, 4) steps; returns (N−1,) errors.

    Each snippet uses steps i … i+length−2 (fewer at the end), the prediction is shifted to the
    GT's first position and scaled by s = Σ(gt·pred)/Σ(pred²) (s = 0 if pred is all zero);
    the error is sqrt(Σ‖s·pred − gt‖²) / n_positions (not an RMSE).
    """
    if pred_steps.shape != gt_steps.shape:
        raise PoseconsError(f"{len(pred_steps)} predicted steps but {len(gt_steps)} ground-truth steps")
    errors = np.empty(len(gt_steps))
    for i in range(len(gt_steps)):
        gt = snippet_positions(gt_steps[i : i + length - 1])
        pred = snippet_positions(pred_steps[i : i + length - 1])
        pred = pred + (gt[0] - pred[0])
        norm = np.sum(pred**2)
        scale = np.sum(gt * pred) / norm if norm > 0 else 0.0
        errors[i] = np.sqrt(np.sum((scale * pred - gt) ** 2)) / len(gt)
    return errors


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity (s, R (3, 3), t (3,)) minimising Σ‖dst − (s·R·src + t)‖² (Umeyama 1991).

    src, dst: (N, 3) corresponding points. With ``with_scale=False`` s = 1 (SE(3) alignment).
    """
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 2:
        raise PoseconsError(f"alignment needs two matching (N ≥ 2, 3) point sets, got {src.shape} and {dst.shape}")
    mu_src, mu_dst = src.mean(0), dst.mean(0)
    a, b = src - mu_src, dst - mu_dst
    U, D, Vt = np.linalg.svd(b.T @ a / len(src))
    S = np.eye(3)
    S[2, 2] = np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0  # keep a proper rotation
    R = U @ S @ Vt
    var_src = np.mean(np.sum(a**2, axis=1))
    scale = float(np.trace(np.diag(D) @ S) / var_src) if with_scale and var_src > 0 else 1.0
    return scale, R, mu_dst - scale * R @ mu_src


def apply_sim3(G: np.ndarray, scale: float, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Map (N, 4, 4) camera → world poses into another world frame: x' = s·R·x + t (rotations R·R_i)."""
    out = G.copy()
    out[:, :3, :3] = R @ G[:, :3, :3]
    out[:, :3, 3] = scale * G[:, :3, 3] @ R.T + t
    return out


def align_trajectory(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, float]:
    """Sim(3)-align (N, 4, 4) predicted poses to GT on their positions; returns (aligned poses, scale)."""
    scale, R, t = umeyama(pred[:, :3, 3], gt[:, :3, 3])
    return apply_sim3(pred, scale, R, t), scale


def scale_alignment(pred: np.ndarray, gt: np.ndarray) -> float:
    """kitti-odom-eval's ``scale`` alignment of (N, 4, 4) poses: one factor s, no rotation or translation,
    minimising Σ‖g_i − s·p_i‖² over the positions p_i, g_i of the poses taken relative to their first
    (inv(P_0)·P_i, inv(G_0)·G_i, as that toolbox does first): s = Σ g_i·p_i / Σ p_i·p_i."""
    p = (np.linalg.inv(pred[0]) @ pred)[:, :3, 3]
    g = (np.linalg.inv(gt[0]) @ gt)[:, :3, 3]
    norm = np.sum(p * p)
    return float(np.sum(g * p) / norm) if norm > 0 else 1.0


def ate_rmse(pred_aligned: np.ndarray, gt: np.ndarray) -> float:
    """RMSE (m) of the position errors of aligned (N, 4, 4) poses."""
    return float(np.sqrt(np.mean(np.sum((pred_aligned[:, :3, 3] - gt[:, :3, 3]) ** 2, axis=1))))


def segment_lengths(path_length: float) -> tuple[list[float], int]:
    """Segment lengths (m) and first-frame step of the odometry errors on a path of this length.

    The devkit's 100 … 800 m (those shorter than the path) every 10th frame; a path under 100 m
    (short synthetic sequences), where the devkit has no segment at all, uses 10 %, 20 %, … 80 %
    of its length from every frame instead.
    """
    if path_length >= KITTI_SEGMENT_LENGTHS[0]:
        return [L for L in KITTI_SEGMENT_LENGTHS if L < path_length], KITTI_FIRST_FRAME_STEP
    return [path_length * k / 10 for k in range(1, 9)], 1


def segment_errors(
    pred: np.ndarray, gt: np.ndarray, lengths: Sequence[float], step: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per-segment translation (m/m) and rotation (rad/m) errors, the KITTI odometry devkit's way.

    Distances are cumulative GT position steps. From every ``step``-th first frame i and for each
    length L, the segment ends at the first frame j with dist[j] > dist[i] + L (strictly greater;
    no such j: no segment). E = inv(inv(P_i)·P_j) · inv(G_i)·G_j; the errors are ‖t_E‖ / L and
    arccos(clamp((tr R_E − 1)/2, −1, 1)) / L. The inverses are general 4×4 ones, as the devkit's:
    the rotations of a pose file are orthonormal only to their printed digits, and the transpose
    would move t_err by ~1e-3 % on KITTI.
    """
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1))])
    firsts = np.arange(0, len(gt), step)
    lasts = np.searchsorted(dist, dist[firsts, None] + np.asarray(lengths, float), side="right")
    row, col = np.nonzero(lasts < len(gt))
    i, j, L = firsts[row], lasts[row, col], np.asarray(lengths, float)[col]
    inv = np.linalg.inv
    err = inv(inv(pred[i]) @ pred[j]) @ (inv(gt[i]) @ gt[j])
    return np.linalg.norm(err[:, :3, 3], axis=1) / L, rotation_angle(err[:, :3, :3]) / L


def odometry_errors(pred: np.ndarray, gt: np.ndarray, alignment: str = "7dof") -> dict:
    """The KITTI odometry devkit's t_err (%) and r_err (°/100 m) of (N, 4, 4) camera → world poses.

    ``7dof``: the prediction is first Sim(3)-aligned to GT on its positions (Umeyama), the usual choice
    for monocular methods; ``6dof``: SE(3), for a prediction in metres; ``scale``: one factor fitted on
    the positions alone (:func:`scale_alignment`, kitti-odom-eval's ``--align scale``), which some
    papers report. Only the scale of an alignment matters here: a rigid change of world frame leaves
    every relative motion inv(P_i)·P_j as it is, so 6-DoF gives the devkit's own numbers (the devkit
    aligns nothing) and is not computed, and ``scale`` multiplies the translations by its factor.
    Then :func:`segment_errors` over :func:`segment_lengths`; t_err and r_err are the means over all
    segments, every length pooled (the devkit's overall average, not a mean of per-length means).
    ``devkit_lengths`` is False on a path under 100 m, whose fractional lengths no paper uses.
    The devkit itself sums distances and errors in single precision; this is float64 throughout.
    Returns also ``alignment``, ``alignment_scale``, ``segment_lengths``, ``n_segments`` (NaN
    errors with no segment, e.g. a GT that never moves).
    """
    if alignment not in ALIGNMENTS:
        raise PoseconsError(f"unknown alignment {alignment!r}; expected one of {ALIGNMENTS}")
    scale = 1.0
    if alignment == "7dof":
        pred, scale = align_trajectory(pred, gt)
    elif alignment == "scale":
        scale = scale_alignment(pred, gt)
        pred = pred.copy()
        pred[:, :3, 3] *= scale
    path = float(np.sum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1)))
    lengths, step = segment_lengths(path) if path > 0 else ([], 1)
    trans, rot = segment_errors(pred, gt, lengths, step)
    return {
        "t_err": float(100 * trans.mean()) if trans.size else float("nan"),
        "r_err": float(np.degrees(rot.mean()) * 100) if rot.size else float("nan"),
        "alignment": alignment,
        "alignment_scale": scale,
        "segment_lengths": [float(L) for L in lengths],
        "devkit_lengths": path >= KITTI_SEGMENT_LENGTHS[0],
        "n_segments": int(trans.size),
    }


def constant_velocity_steps(gt_steps: np.ndarray, mode: str = "first") -> np.ndarray:
    """A motion model with no image input, (N−1, 4, 4): every step equals the first GT step
    (``first``), or the previous GT step (``previous``, the first step is GT's own)."""
    if mode == "first":
        return np.broadcast_to(gt_steps[0], gt_steps.shape).copy()
    if mode == "previous":
        return np.concatenate([gt_steps[:1], gt_steps[:-1]])
    raise PoseconsError(f"unknown constant-velocity mode {mode!r}; expected one of {CONST_VELOCITY_MODES}")


def trajectory_metrics(pred_global: np.ndarray, gt_global: np.ndarray, alignment: str = "7dof") -> dict:
    """All pose metrics of (N, 4, 4) predicted against (N, 4, 4) GT camera → world poses.

    The snippet ATE uses the steps of both trajectories; the full ATE the predicted trajectory after
    Sim(3) alignment to GT, which absorbs the unknown monocular scale; t_err / r_err
    (:func:`odometry_errors`) the given ``alignment``.
    """
    errors = snippet_errors(relative_from_global(pred_global), relative_from_global(gt_global))
    aligned, scale = align_trajectory(pred_global, gt_global)
    return {
        "ate_mean": float(errors.mean()),
        "ate_std": float(errors.std()),
        "n_snippets": int(errors.size),
        "ate_full_rmse": ate_rmse(aligned, gt_global),
        "sim3_scale": scale,
        **odometry_errors(pred_global, gt_global, alignment),
    }


def pose_metrics(
    pred_global: np.ndarray, gt_global: np.ndarray, const_velocity: str = "first", alignment: str = "7dof"
) -> dict:
    """:func:`trajectory_metrics` of (N, 4, 4) predicted camera → world poses (e.g. chained pose-net steps,
    :func:`global_from_relative`) plus the same metrics for a constant-velocity baseline
    (``const_velocity`` sub-dict), which shows how much of a score needs no images at all."""
    if len(gt_global) < 2:
        raise PoseconsError(f"pose evaluation needs at least 2 ground-truth poses, got {len(gt_global)}")
    if len(pred_global) != len(gt_global):
        raise PoseconsError(f"{len(pred_global)} predicted poses but {len(gt_global)} ground-truth poses")
    baseline = global_from_relative(constant_velocity_steps(relative_from_global(gt_global), const_velocity))
    return {
        **trajectory_metrics(pred_global, gt_global, alignment),
        "n_frames": len(gt_global),
        "const_velocity": {"mode": const_velocity, **trajectory_metrics(baseline, gt_global, alignment)},
    }
