"""Signs that a run's depth has collapsed, read from the training outputs alone (no ground truth).

A run from scratch can end with a depth that explains nothing: every disparity pinned at one end of
its sigmoid (which then passes no gradient, so the run stays there), a depth that is nearly the same
everywhere in the image, or a depth and motion that reproduce the target no better than leaving the
source frames unwarped (as an inverted depth does). :func:`collapse_signs` measures each on a training
batch; :class:`CollapseWatch` follows them over the logged steps, warns once a problem has held on
consecutive logged steps after the lr warm-up, and judges the last few logged steps at the end
(``train_summary.json``'s ``"collapse"``, and ``posecons demo`` fails on it).
"""

from __future__ import annotations

import math

import torch

# A sigmoid output below 0.01 or above 0.99 passes under 1 % of its largest gradient.
PINNED_END = 0.01
# Thresholds of a collapse (experiments/investigation.md §30 measures them on runs that learnt and runs
# that did not): more than half of the pixels pinned; a log-disparity spread within an image below 0.05,
# that is depths within about ±5 % of the image's own mean; a warp that gains nothing over no motion.
PINNED_SHARE = 0.5
FLAT_SPREAD = 0.05
NO_GAIN = 0.0
PERSIST = 2  # consecutive logged steps a problem must hold before it is reported


def collapse_signs(outputs: dict) -> dict[str, float]:
    """The signs of a collapse in a training step's ``outputs`` (of :meth:`PoseConsModel.forward`):

    - ``warped_fraction``: share of pixels where a warped source beat the unwarped ones (the rest the
      auto-mask hides from the loss);
    - ``far_fraction`` / ``near_fraction``: shares of full-scale disparity sigmoids pinned at the far end
      (< 0.01) and at the near end (> 0.99, every such pixel at ``model.min_depth``);
    - ``log_disp_spread``: the standard deviation of the log of the full-scale disparity sigmoid within
      each image, averaged over the batch (0 for a constant depth; a sigmoid scaled by one factor per
      image does not change it);
    - ``warp_gain``: 1 − best warped error / best unwarped error at full scale (≤ 0: the depth and pose
      explain the target no better than no motion; NaN without the auto-mask).
    """
    disp = outputs["disp"][0].detach().float()
    log_disp = torch.log(disp.clamp_min(torch.finfo(torch.float32).tiny)).flatten(1)
    return {
        "warped_fraction": float(outputs["automask"].float().mean()),
        "far_fraction": float((disp < PINNED_END).float().mean()),
        "near_fraction": float((disp > 1 - PINNED_END).float().mean()),
        "log_disp_spread": float(log_disp.std(1).mean()),
        "warp_gain": float(outputs["warp_gain"]),
    }


def problems(signs: dict[str, float]) -> dict[str, str]:
    """What ``signs`` (of :func:`collapse_signs`) show wrong: kind → a phrase; empty for a healthy step."""
    found = {}
    for end in ("far", "near"):
        share = signs[f"{end}_fraction"]
        if share > PINNED_SHARE:
            found[f"pinned_{end}"] = (
                f"the disparity is pinned at the {end} end of its range on {share:.0%} of the pixels "
                "(its sigmoid passes no gradient there)"
            )
    if signs["log_disp_spread"] < FLAT_SPREAD:
        found["flat"] = (
            f"the depth is nearly constant within each image (log-disparity spread {signs['log_disp_spread']:.3f})"
        )
    if signs["warp_gain"] <= NO_GAIN:  # False for NaN: no auto-mask, no verdict
        found["no_gain"] = (
            f"the warped frames match the target no better than the unwarped ones (gain {signs['warp_gain']:+.3f})"
        )
    return found


class CollapseWatch:
    """Follows :func:`collapse_signs` over the logged steps of a run from step ``start`` on (before it,
    the lr warm-up is still settling the motion's direction, and the untrained depth is flat by
    construction). A problem is said once it has held on :data:`PERSIST` logged steps in a row; the
    run's verdict at its end judges the mean of the signs over its last :data:`PERSIST` + 1 logged
    steps, so that one batch neither hides nor makes a collapse."""

    def __init__(self, start: int):
        self.start = start
        self.step, self.signs = 0, {}
        self._streak: dict[str, int] = {}
        self._last: list[dict[str, float]] = []

    def update(self, step: int, signs: dict[str, float]) -> list[str]:
        """Record ``signs`` of ``step``; returns the problems that have just held for :data:`PERSIST`
        logged steps in a row (each is said once per streak)."""
        self.step, self.signs = step, signs
        if step < self.start:
            return []
        self._last = (self._last + [signs])[-(PERSIST + 1) :]
        found = problems(signs)
        self._streak = {kind: self._streak.get(kind, 0) + 1 for kind in found}
        return [text for kind, text in found.items() if self._streak[kind] == PERSIST]

    def summary(self) -> dict:
        """What ``train_summary.json`` records: the last logged step's signs and the problems of the
        mean signs of the last logged steps (empty: no sign of a collapse at the end of the run)."""
        mean = {k: sum(s[k] for s in self._last) / len(self._last) for k in self.signs} if self._last else {}
        return {
            "step": self.step,
            "signs": {k: (v if math.isfinite(v) else None) for k, v in self.signs.items()},
            "problems": list(problems(mean).values()) if mean else [],
        }
