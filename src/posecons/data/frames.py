"""The shared training-sample logic of the KITTI raw and odometry datasets.

Sample contract (the model relies on it):
    ``frames``     float32 (F, 3, H, W) in [0, 1], in ``frame_ids`` order, flipped if drawn;
    ``intrinsics`` float32 (3, 3) K normalised by image size, mirrored when flipped (``flip_intrinsics``);
    ``color_aug``  float32 (4,) jitter factors (b, c, s, h), (1, 1, 1, 0) when not drawn;
    ``index`` int, ``folder`` str, ``frame`` int, ``side`` str;
    ``motions``    float32 (F − 1, 4, 4) with ``with_motion``: the camera's true motion T_{f←0} (metres)
                   from the target to each source, from the drive's GNSS/INS (raw) or ground-truth
                   poses (odometry), mirrored (M·T·M, M = diag(−1, 1, 1, 1)) when flipped.

With a frame cache (:mod:`.cache`) the resized pixels come from it instead of the image files;
everything else, and every value of the sample, is the same.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from torch.utils.data import Dataset, DistributedSampler, Sampler

from ..errors import PoseconsError
from ..geometry import flip_intrinsics, mirror_pose
from .augment import IDENTITY_JITTER, draw_augmentation, sample_rng
from .cache import FrameCache
from .calib import KITTI_FIXED_K
from .images import image_suffix, load_resized, to_float
from .splits import SplitLine, SplitSource, read_split


class EpochOrder(Sampler):
    """A rank's shuffled order of one epoch as ``(epoch, index)`` keys of a :class:`FrameDataset`:
    the keys carry the epoch to persistent loader workers, whose dataset copies cannot be told it."""

    def __init__(self, dataset: Dataset, world: int, rank: int, seed: int) -> None:
        self.shuffle = DistributedSampler(dataset, world, rank, shuffle=True, seed=seed, drop_last=True)
        self.keys: list[tuple[int, int]] = []

    def start(self, epoch: int, skip: int = 0) -> None:
        """Epoch ``epoch``'s order from its ``skip``-th sample on (a resumed epoch)."""
        self.shuffle.set_epoch(epoch)
        self.keys = [(epoch, i) for i in list(self.shuffle)[skip:]]

    def __iter__(self):
        return iter(self.keys)

    def __len__(self) -> int:
        return len(self.keys)


class FrameDataset(Dataset):
    """Base class: subclasses say where a frame's image lives and what its calibrated K is.

    ``split``: a split file or its lines; ``frame_ids``: offsets to load (target first);
    ``train=False`` disables augmentation; ``calib_intrinsics=False`` uses KITTI's fixed K
    (fx=0.58, fy=1.92, cx=cy=0.5); augmentation draws depend only on (seed, epoch, index);
    ``check_files`` stats every needed image (and cached frame) up front so a bad split fails
    before training; ``cache``: a :class:`~posecons.data.cache.FrameCache` to read the resized
    frames from; ``jpeg_draft``: decode JPEGs at a reduced DCT scale (:func:`~posecons.data.images.load_resized`).
    """

    def __init__(
        self,
        data_path: str | Path,
        split: SplitSource,
        height: int,
        width: int,
        frame_ids: Sequence[int] = (0, -1, 1),
        img_ext: str = ".png",
        train: bool = True,
        calib_intrinsics: bool = True,
        flip_prob: float = 0.5,
        jitter_prob: float = 0.5,
        seed: int = 0,
        check_files: bool = True,
        skip_incomplete: bool = False,
        cache: FrameCache | None = None,
        jpeg_draft: bool = False,
        with_motion: bool = False,
    ) -> None:
        self.data_path = Path(data_path)
        self.lines: list[SplitLine] = read_split(split)
        self.height, self.width = int(height), int(width)
        self.frame_ids = tuple(int(f) for f in frame_ids)
        self.img_ext = image_suffix(img_ext)
        self.train = train
        self.calib_intrinsics = calib_intrinsics
        self.flip_prob, self.jitter_prob = (flip_prob, jitter_prob) if train else (0.0, 0.0)
        self.seed = seed
        self.skip_incomplete = skip_incomplete
        self.cache = cache
        self.jpeg_draft = jpeg_draft
        if check_files:
            self.check_files()
        # Read once here (each line's pose files), not again for every sample of every epoch.
        self.motions = [self.motion(line) for line in self.lines] if with_motion else None
        self._first = {(line.folder, line.side): line for line in reversed(self.lines)}  # first line per camera
        self._sizes: dict[tuple[str, str], tuple[Path, tuple[int, int]]] = {}

    # -- what subclasses provide -------------------------------------------------------------
    def image_path(self, line: SplitLine, frame: int) -> Path:
        """Path of the image of ``line``'s camera at ``frame``."""
        raise NotImplementedError

    def calib_k(self, line: SplitLine) -> np.ndarray:
        """Normalised (3, 3) K of ``line``'s camera from its calibration file."""
        raise NotImplementedError

    def camera_poses(self, line: SplitLine, frames: list[int]) -> np.ndarray:
        """Metric poses (N, 4, 4) of ``line``'s camera at ``frames`` (camera → one world frame)."""
        raise NotImplementedError

    # -- shared logic -------------------------------------------------------------------------
    def motion(self, line: SplitLine) -> np.ndarray:
        """float32 (F − 1, 4, 4): the camera's motion T_{f←0} = C_f⁻¹ C_0 from ``line``'s target
        frame to each source, which maps target-camera points into the source camera."""
        try:
            c = self.camera_poses(line, [line.frame + f for f in self.frame_ids])
        except PoseconsError as exc:
            raise PoseconsError(
                f"{exc} (loss.velocity_weight, model.known_motion and known_rotation need the camera's motion)"
            ) from exc
        return (np.linalg.inv(c[1:]) @ c[0]).astype(np.float32)

    def check_files(self) -> None:
        """Fail early, naming the split line, when a frame or its neighbours are missing; with
        ``skip_incomplete``, drop such lines instead (e.g. near drive ends when the frame offsets
        are wider than the split was made for) and say how many."""
        complete = []
        for line in self.lines:
            missing = [o for o in self.frame_ids if not self.image_path(line, line.frame + o).is_file()]
            if not missing:
                complete.append(line)
            elif not self.skip_incomplete:
                path = self.image_path(line, line.frame + missing[0])
                raise PoseconsError(
                    f"{line.where}: frame {line.frame}{missing[0]:+d} of '{line}' missing: {path} "
                    "(data.skip_incomplete=true drops such lines)"
                )
        if len(complete) < len(self.lines):
            source = self.lines[0].where.rsplit(":", 1)[0]
            print(
                f"{source}: dropped {len(self.lines) - len(complete)} of {len(self.lines)} lines whose frames "
                f"{list(self.frame_ids)} do not all exist (data.skip_incomplete)",
                file=sys.stderr,
            )
            self.lines = complete
            if not complete:
                raise PoseconsError(f"{source}: no line has all of its frames {list(self.frame_ids)}")
        for line in self.lines if self.cache is not None else []:
            for o in self.frame_ids:
                cached = self.cache.file(self.image_path(line, line.frame + o))
                if not cached.is_file():
                    raise PoseconsError(
                        f"{line.where}: frame {line.frame}{o:+d} of '{line}' is not in the frame cache "
                        f"{self.cache.folder} ({cached} missing); build the cache again with `posecons cache`"
                    )

    def intrinsics(self, line: SplitLine) -> np.ndarray:
        """Normalised (3, 3) K: the calibrated one, or KITTI's fixed K when calibration is off."""
        return self.calib_k(line) if self.calib_intrinsics else KITTI_FIXED_K

    def reference_size(self, line: SplitLine) -> tuple[Path, tuple[int, int]]:
        """The image of the first split line of ``line``'s drive and camera, and its (width, height):
        every frame of that drive must have this size (K is normalised by it)."""
        key = (line.folder, line.side)
        if key not in self._sizes:
            first = self._first[key]
            path = self.image_path(first, first.frame)
            try:
                with Image.open(path) as img:
                    self._sizes[key] = (path, img.size)
            except OSError as exc:
                raise PoseconsError(f"{path}: unreadable image ({exc})") from exc
        return self._sizes[key]

    def __len__(self) -> int:
        return len(self.lines)

    def load_frame(self, path: Path, flip: bool, like: tuple[Path, tuple[int, int]] | None = None) -> torch.Tensor:
        """Decode and resize exactly as evaluation and inference do (``resize_rgb``; with
        ``jpeg_draft`` a reduced JPEG decode first), or read what the cache holds of that, then flip:
        (3, H, W) float32 in [0, 1]; ``like``: see :func:`~posecons.data.images.load_rgb`."""
        if self.cache is not None:
            pixels = self.cache.load(path)
        else:
            pixels = load_resized(path, self.height, self.width, like, self.jpeg_draft)
        image = torch.from_numpy(to_float(pixels))
        return image.flip(-1) if flip else image

    def __getitem__(self, key: int | tuple[int, int]) -> dict:
        """Sample ``index`` or ``(epoch, index)``: a training sample's augmentation is drawn from its
        seed, epoch and index (an int index is epoch 0), so it is the same in any loader worker."""
        epoch, index = key if isinstance(key, tuple) else (0, key)
        line = self.lines[index]
        if self.train:
            flip, jitter = draw_augmentation(sample_rng(self.seed, epoch, index), self.flip_prob, self.jitter_prob)
        else:
            flip, jitter = False, np.array(IDENTITY_JITTER, dtype=np.float32)
        like = None if self.cache is not None else self.reference_size(line)  # the cache build checked sizes
        frames = torch.stack(
            [self.load_frame(self.image_path(line, line.frame + f), flip, like) for f in self.frame_ids]
        )
        k = torch.from_numpy(self.intrinsics(line).astype(np.float32))
        extra = {}
        if self.motions is not None:
            motion = torch.from_numpy(self.motions[index])
            extra["motions"] = mirror_pose(motion) if flip else motion
        return {
            "frames": frames,
            "intrinsics": flip_intrinsics(k, self.width) if flip else k,
            "color_aug": torch.from_numpy(jitter),
            "index": index,
            "folder": line.folder,
            "frame": line.frame,
            "side": line.side,
            **extra,
        }
