"""The one prediction path: batching, resizing, post-processing and step chaining over any Predictor."""

import numpy as np
import pytest
import torch
from PIL import Image

from posecons.evaluation.evaluate import model_steps
from posecons.inference.backend import Predictor, post_process_disparity, predict_batches
from posecons.inference.media import Frame


def test_post_process_blends_towards_the_mirrored_prediction_at_the_left_border():
    W = 100
    disp, mirrored = torch.ones(1, 1, 2, W), torch.full((1, 1, 2, W), 3.0)
    out = post_process_disparity(disp, mirrored)[0, 0, 0]
    assert out[0] == 3.0 and out[-1] == 1.0  # each border comes from the prediction that saw it inside
    assert out[50] == pytest.approx(2.0)  # the middle is the mean
    assert torch.equal(post_process_disparity(disp, disp), disp)


class _MeanPosePredictor(Predictor):
    """Stands in for the networks: disparity = image mean per pixel; T_{b←a} = [I | (mean a, mean b, 0)]
    shows which frames were paired."""

    name, height, width, has_pose = "fake", 4, 8, True

    def disparity(self, images):
        return torch.from_numpy(images.mean(1, keepdims=True))

    def pose(self, a, b):
        T = np.tile(np.eye(4), (len(a), 1, 1))
        T[:, 0, 3], T[:, 1, 3] = a.mean((1, 2, 3)), b.mean((1, 2, 3))
        return T


@pytest.mark.parametrize("batch_size", [1, 2, 4, 7])
def test_predict_steps_pairs_consecutive_frames_across_batches(tmp_path, batch_size):
    paths = []
    for i in range(7):
        paths.append(tmp_path / f"{i:06d}.png")
        Image.new("RGB", (8, 4), (20 * i,) * 3).save(paths[-1])
    steps = model_steps(_MeanPosePredictor(), paths, batch_size)
    levels = 20 * np.arange(7) / 255
    assert np.allclose(steps[:, 0, 3], levels[:-1]) and np.allclose(steps[:, 1, 3], levels[1:])


def test_batches_resize_to_the_network_and_post_processing_keeps_a_symmetric_prediction():
    frames = [Frame(str(i), i, 0.0, np.full((12, 30, 3), 10 * i, np.uint8)) for i in range(5)]
    plain = list(predict_batches(_MeanPosePredictor(), frames, 2))
    assert [len(f) for f, _, _ in plain] == [2, 2, 1]
    assert all(images.shape[1:] == (3, 4, 8) and disps.shape[1:] == (1, 4, 8) for _, images, disps in plain)
    mirrored = predict_batches(_MeanPosePredictor(), frames, 2, post_process=True)
    assert all(torch.allclose(a[2], b[2]) for a, b in zip(plain, mirrored))
    assert all(disps is None for _, _, disps in predict_batches(_MeanPosePredictor(), frames, 3, depth=False))
