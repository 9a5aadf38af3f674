"""Frame sources (one image, a folder of images, a video) that stream decoded frames, the
side-by-side video writer.

Sources can be iterated more than once (each pass re-opens the file), so scale calibration can
look at the first frames before the main pass without holding a video in memory.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
from PIL import Image

from ..data.images import load_rgb
from ..errors import PoseconsError

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".ppm")
VIDEO_EXTENSIONS = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v")
DEFAULT_FPS = 10.0  # KITTI's frame rate: timestamps of image folders are index / fps


@dataclass
class Frame:
    """One decoded input frame.

    name: output file stem (the image's stem, or the 6-digit frame index of a video);
    index: position in the sequence; time: seconds; image: (H, W, 3) uint8 RGB.
    """

    name: str
    index: int
    time: float
    image: np.ndarray

    @property
    def size(self) -> tuple[int, int]:
        """(height, width) of the original frame."""
        return self.image.shape[0], self.image.shape[1]


def frames_from_paths(paths: Iterable[Path], fps: float = DEFAULT_FPS) -> Iterator[Frame]:
    """Decode images one by one (e.g. a split's or an odometry sequence's frames) as :class:`Frame`."""
    for index, path in enumerate(paths):
        yield Frame(path.stem, index, index / fps, np.asarray(load_rgb(path)))


class FrameSource:
    """Re-iterable stream of :class:`Frame` from an image, a folder of images or a video."""

    def __init__(self, path: str | Path, fps: float = DEFAULT_FPS):
        self.path = Path(path)
        self.fps = fps
        if not self.path.exists():
            raise PoseconsError(f"{self.path}: input does not exist")
        if self.path.is_dir():
            self.kind = "folder"
            self.images = sorted(p for p in self.path.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS)
            if not self.images:
                raise PoseconsError(f"{self.path}: no images ({', '.join(IMAGE_EXTENSIONS)}) in this folder")
        elif self.path.suffix.lower() in IMAGE_EXTENSIONS:
            self.kind, self.images = "image", [self.path]
        elif self.path.suffix.lower() in VIDEO_EXTENSIONS:
            if self.path.stat().st_size == 0:
                raise PoseconsError(f"{self.path}: the video file is empty")
            self.kind, self.images = "video", []
            self.video_fps, self.num_frames = self._probe_video()
        else:
            raise PoseconsError(
                f"{self.path}: unsupported input type {self.path.suffix!r}; give an image "
                f"({', '.join(IMAGE_EXTENSIONS)}), a folder of images or a video "
                f"({', '.join(VIDEO_EXTENSIONS)})"
            )

    @property
    def is_video(self) -> bool:
        return self.kind == "video"

    def __len__(self) -> int:
        """Number of frames (for a video, the container's count, which may be an estimate)."""
        return self.num_frames if self.is_video else len(self.images)

    def __iter__(self) -> Iterator[Frame]:
        if self.is_video:
            yield from self._video_frames()
            return
        yield from frames_from_paths(self.images, self.fps)

    def _open(self):
        import av

        try:
            container = av.open(str(self.path))
        except (av.FFmpegError, OSError) as exc:
            raise PoseconsError(f"{self.path}: unreadable video ({exc})") from exc
        if not container.streams.video:
            container.close()
            raise PoseconsError(f"{self.path}: the file holds no video stream")
        return container

    def _probe_video(self) -> tuple[float, int]:
        with self._open() as container:
            stream = container.streams.video[0]
            rate = float(stream.average_rate) if stream.average_rate else self.fps
            return rate, int(stream.frames or 0)

    def _video_frames(self) -> Iterator[Frame]:
        import av

        count = 0
        with self._open() as container:
            stream = container.streams.video[0]
            try:
                for count, frame in enumerate(container.decode(stream), start=1):
                    index = count - 1
                    time = float(frame.time) if frame.time is not None else index / self.video_fps
                    yield Frame(f"{index:06d}", index, time, frame.to_ndarray(format="rgb24"))
            except av.FFmpegError as exc:
                raise PoseconsError(f"{self.path}: video decoding failed at frame {count} ({exc})") from exc
        if count == 0:
            raise PoseconsError(f"{self.path}: the video has no decodable frames")


class SideBySideWriter:
    """H.264 MP4 of input | colour-mapped depth, frame by frame (odd sizes lose their last row/column,
    since yuv420p needs even dimensions)."""

    def __init__(self, path: Path, fps: float):
        import av

        self.path = path
        self.container = av.open(str(path), mode="w")
        x264 = "libx264" in av.codecs_available
        self.stream = self.container.add_stream(
            "libx264" if x264 else "mpeg4",
            rate=Fraction(fps).limit_denominator(1001),
            # x264's "veryfast": 3.4× less time a frame than its default "medium" on a 1920×540 side-by-side
            # clip (32 against 110 ms), at a slightly smaller file
            options={"preset": "veryfast"} if x264 else {},
        )
        self.stream.pix_fmt = "yuv420p"
        self.size: tuple[int, int] | None = None

    def write(self, image: np.ndarray, depth_rgb: np.ndarray) -> None:
        """image, depth_rgb: (H, W, 3) uint8 of the same size."""
        import av

        frame = np.concatenate([image, depth_rgb], 1)
        h, w = frame.shape[0] // 2 * 2, frame.shape[1] // 2 * 2
        if self.size is None:
            self.size = (h, w)
            self.stream.height, self.stream.width = h, w
        elif self.size != (h, w):  # a video's frames share one size; resize any stray frame
            frame = np.asarray(Image.fromarray(frame).resize((self.size[1], self.size[0]), Image.BILINEAR))
        frame = np.ascontiguousarray(frame[: self.size[0], : self.size[1]])
        for packet in self.stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
            self.container.mux(packet)

    def close(self) -> None:
        for packet in self.stream.encode():
            self.container.mux(packet)
        self.container.close()
