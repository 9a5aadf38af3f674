import dataclasses

import pytest
import torch

from posecons import terms
from posecons.config import CONSTRAINTS, RULES, LossConfig
from posecons.model import PoseConsModel
from posecons.pose_source import KnownMotion, KnownRotation, NetworkPoses, pose_source
from posecons.terms import StepContext, Term
from test_model import make_config, random_batch


class MeanDisparity(Term):
    """The term of CONTRIBUTING.md's worked example (its equation inline): the target's mean disparity."""

    name, weight_key = "mean_disparity", "mean_disparity_weight"

    def __call__(self, ctx: StepContext) -> torch.Tensor:
        return ctx.disps[0].mean()


def with_mean_disparity(weight: float, constraints=()):
    config = make_config(constraints)
    config.loss.mean_disparity_weight = weight  # stands in for the LossConfig field a real term adds
    return config


def test_a_registered_term_is_in_the_losses_and_adds_its_weight_times_itself_to_the_total(monkeypatch):
    """Caught: the term left out of TERMS (its key missing), its weight not applied or not summed."""
    monkeypatch.setattr(terms, "TERMS", [*terms.TERMS, MeanDisparity])
    model = PoseConsModel(with_mean_disparity(0.25, ["cyc"]))
    outputs, losses = model(random_batch())
    assert torch.equal(losses["mean_disparity"], outputs["disp"][0].mean())
    expected = losses["photometric"] + losses["smoothness"] + 0.1 * losses["cyc"] + 0.25 * losses["mean_disparity"]
    torch.testing.assert_close(losses["total"], expected)
    assert "mean_disparity" not in PoseConsModel(with_mean_disparity(0.0))(random_batch())[1]  # weight 0: off


def test_every_term_has_one_name_and_a_weight_field_with_a_rule():
    """Caught: two terms of one name, a weight key that is no LossConfig field or has no rule, a
    constraint term whose name loss.constraints does not accept."""
    names = [t.name for t in terms.TERMS]
    assert len(set(names)) == len(names)
    fields = {f.name for f in dataclasses.fields(LossConfig)}
    for term in terms.TERMS:
        assert term.weight_key in fields and f"loss.{term.weight_key}" in RULES, term.name
    assert {t.name for t in terms.TERMS if t.constraint} == set(CONSTRAINTS)


def test_the_pose_net_sees_each_pair_once_however_many_terms_ask_for_it():
    """cyc and skip both read (−1, +1): 2 temporal + the reversed 2 + identity + that pair once.
    Caught: a pair asked for twice run twice; the temporal pairs not first."""
    model = PoseConsModel(make_config(["fb", "id", "cyc"], **{"loss.skip_weight": 0.1}))
    assert model.pose_pairs(model.terms) == [(-1, 0), (0, 1), (0, -1), (1, 0), (0, 0), (-1, 1)]
    calls = []
    model.pose_net.encoder.register_forward_hook(lambda mod, inp, out: calls.append(inp[0].shape[0]))
    _, losses = model(random_batch(b=3))
    assert calls == [6 * 3] and {"fb", "id", "cyc", "skip"} <= set(losses)


def test_validation_leaves_out_the_constraints_and_keeps_the_other_terms():
    model = PoseConsModel(make_config(["fb", "cyc"], **{"loss.saturation_weight": 0.5}))
    assert [t.name for t in model.active_terms(0, with_constraints=False)] == ["saturation"]
    assert [t.name for t in model.active_terms(0)] == ["fb", "cyc", "saturation"]


@pytest.mark.parametrize(
    "settings, source",
    [
        ({}, NetworkPoses),
        ({"model.known_rotation": "true"}, KnownRotation),
        ({"model.known_motion": "true"}, KnownMotion),
    ],
)
def test_the_pose_source_is_the_one_the_config_chooses_and_follows_a_new_config(settings, source):
    assert type(pose_source(make_config(**settings).model)) is source
    model = PoseConsModel(make_config())
    model.config = make_config(**settings)  # as experiments/tools/early_steps.py switches settings mid-run
    assert type(model.pose_source) is source


def test_a_term_that_needs_the_motions_names_its_setting_when_the_batch_has_none():
    model = PoseConsModel(make_config(**{"loss.velocity_weight": 0.5}))
    with pytest.raises(ValueError, match=r"loss.velocity_weight need batch\['motions'\]"):
        model(random_batch())
