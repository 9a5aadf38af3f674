"""From a config and a data path to the training and validation datasets."""

from __future__ import annotations

from pathlib import Path

from ..config import Config
from ..errors import PoseconsError
from .cache import open_cache
from .frames import FrameDataset
from .kitti_odometry import KittiOdometryDataset
from .kitti_raw import KittiRawDataset
from .splits import BUNDLED, bundled_names


def split_files(config: Config, data_path: str | Path, split_dir: str | Path | None) -> tuple[Path, Path | None]:
    """(train split, val split or None) from --split-dir, else DATA/splits/<data.split>, else the
    bundled split of that name (eigen_zhou, eigen_full, odom)."""
    data_path = Path(data_path)
    if not data_path.is_dir():
        raise PoseconsError(f"data path {data_path} is not a directory")
    folder = Path(split_dir) if split_dir else data_path / "splits" / config.data.split
    if not split_dir and not folder.is_dir() and (BUNDLED / config.data.split / "train_files.txt").is_file():
        folder = BUNDLED / config.data.split
    train = folder / "train_files.txt"
    if not train.is_file():
        raise PoseconsError(
            f"{train}: training split file not found (data.split={config.data.split!r}; bundled: "
            f"{', '.join(bundled_names())}; pass --split-dir or run `posecons synth` / "
            "`posecons prepare` to create one)"
        )
    val = folder / "val_files.txt"
    return train, val if val.is_file() else None


def build_dataset(config: Config, data_path: str | Path, split_file: Path, train: bool) -> FrameDataset:
    """The training (``train=True``: augmented) or validation dataset of ``split_file``, reading
    its frames from ``data.cache_dir`` when that is set (checked to fit this config and split)."""
    m, d = config.model, config.data
    role = "train" if train else "val"
    cache = open_cache(d.cache_dir, config, data_path, split_file, role) if d.cache_dir else None
    cls = KittiOdometryDataset if d.dataset == "kitti_odom" else KittiRawDataset
    return cls(
        data_path,
        split_file,
        m.height,
        m.width,
        frame_ids=m.frame_ids,
        img_ext=d.img_ext,
        train=train,
        calib_intrinsics=d.calib_intrinsics,
        flip_prob=d.flip_prob,
        jitter_prob=d.jitter_prob,
        seed=config.train.seed,
        skip_incomplete=d.skip_incomplete,
        cache=cache,
        jpeg_draft=d.jpeg_draft,
        with_motion=config.loss.velocity_weight > 0 or m.known_motion or m.known_rotation,
    )
