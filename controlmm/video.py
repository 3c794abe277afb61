"""Writing animations (MP4 through imageio-ffmpeg's bundled ffmpeg, GIF through Pillow)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from controlmm.atomic import atomic_path
from controlmm.errors import ControlMMError

VIDEO_FORMATS = (".mp4", ".gif")


def write_video(path: str | Path, frames: Iterable[np.ndarray], fps: float) -> int:
    """Write RGB frames (H, W, 3) uint8 to ``.mp4`` or ``.gif`` atomically; return the count."""
    import imageio.v2 as imageio  # only when a video is written (it brings its ffmpeg plugin)

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_FORMATS:
        raise ControlMMError(f"unknown animation format '{path.suffix}'; allowed: {', '.join(VIDEO_FORMATS)}")
    count = 0
    with atomic_path(path) as tmp:
        if suffix == ".mp4":
            writer = imageio.get_writer(
                tmp,
                format="FFMPEG",
                mode="I",
                fps=fps,
                codec="libx264",
                quality=7,
                macro_block_size=8,
                pixelformat="yuv420p",
            )
        else:
            writer = imageio.get_writer(tmp, format="GIF", mode="I", duration=1000.0 / fps, loop=0)
        try:
            for frame in frames:
                frame = np.asarray(frame)
                if suffix == ".mp4":
                    h, w = frame.shape[:2]
                    frame = frame[: h - h % 2, : w - w % 2]
                writer.append_data(frame[..., :3])
                count += 1
        finally:
            writer.close()
        if count == 0:
            raise ControlMMError(f"no frames to write to '{path}'")
    return count
