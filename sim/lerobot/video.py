"""Video features through PyAV: frames encoded as LeRobot encodes them, and read back.

One mp4 per (video key, chunk, file) holds the episodes one after another; frame i of the file
has the presentation time i / fps, so an episode's frames lie from its
`videos/<key>/from_timestamp` on (LeRobot decodes `from_timestamp + timestamp` within 1/fps).
"""

from __future__ import annotations

import os
from fractions import Fraction
from pathlib import Path

import numpy as np

from sim.core.errors import UserError
from sim.lerobot.format import ENCODER, PIX_FMT, VIDEO_CODEC, VIDEO_OPTIONS


def _av():
    os.environ.setdefault("SVT_LOG", "1")  # SVT-AV1 prints its settings on stderr otherwise
    import av

    return av


def encoder_available() -> bool:
    """PyAV is installed with an AV1 encoder (SVT-AV1) and decoder."""
    try:
        av = _av()
        av.codec.Codec(VIDEO_CODEC, "w")
        av.codec.Codec("av1", "r")
    except Exception:  # no PyAV, or one built without the codec
        return False
    return True


class VideoWriter:
    """Frames appended to one mp4 (AV1, yuv420p, a key frame every second frame, crf 30)."""

    def __init__(self, path: Path, *, fps: int, height: int, width: int) -> None:
        av = _av()
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path, self.frames = path, 0
        self._container = av.open(str(path), "w")
        stream = self._container.add_stream(VIDEO_CODEC, fps, options=dict(VIDEO_OPTIONS))
        stream.pix_fmt, stream.width, stream.height = PIX_FMT, width, height
        stream.time_base = Fraction(1, fps)
        self._stream, self._fps = stream, fps

    def append(self, frames: np.ndarray) -> None:
        """uint8 (T, H, W, 3) frames after the ones already written."""
        av = _av()
        for frame in frames:
            vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")
            vf.pts, vf.time_base = self.frames, Fraction(1, self._fps)
            for packet in self._stream.encode(vf):
                self._container.mux(packet)
            self.frames += 1

    @property
    def size_in_mb(self) -> float:
        return self.path.stat().st_size / 1024**2 if self.path.exists() else 0.0

    def close(self) -> None:
        for packet in self._stream.encode():
            self._container.mux(packet)
        self._container.close()


def video_info(path: Path) -> dict:
    """The feature's "info" in meta/info.json, as LeRobot's get_video_info writes it: what the
    file's stream says, then the encoder's settings, then is_depth_map."""
    av = _av()
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        info = {
            "video.height": s.height,
            "video.width": s.width,
            "video.codec": s.codec.canonical_name,
            "video.pix_fmt": s.pix_fmt,
            "video.fps": int(s.base_rate),
            "video.channels": 3,
            "has_audio": bool(c.streams.audio),
        }
    for name, value in ENCODER.items():
        info.setdefault(f"video.{name}", value)
    return info | {"is_depth_map": False}


def read_frames(path: Path, start_s: float, n: int, fps: int) -> np.ndarray:
    """uint8 (n, H, W, 3): the frames at start_s, start_s + 1/fps, ... of one video file, each
    the decoded frame nearest its time (within half a frame); a UserError naming the file when
    one is missing."""
    av = _av()
    want = [round(start_s * fps) + i for i in range(n)]
    got: dict[int, np.ndarray] = {}
    try:
        with av.open(str(path)) as c:
            stream = c.streams.video[0]
            tb = stream.time_base
            c.seek(max(0, round(start_s / tb) - 1), backward=True, any_frame=False, stream=stream)
            for frame in c.decode(stream):
                if frame.pts is None:
                    continue
                t = float(frame.pts * tb)
                k = round(t * fps)
                if abs(t * fps - k) <= 0.5 and want[0] <= k <= want[-1]:
                    got[k] = frame.to_ndarray(format="rgb24")
                if k >= want[-1]:
                    break
    except (OSError, ValueError) as e:  # av.error.* derive from these
        raise UserError(f"{path}: cannot decode the video ({e})") from None
    missing = [k for k in want if k not in got]
    if missing:
        raise UserError(
            f"{path}: no frame at {missing[0] / fps:.3f} s ({len(missing)} of {n} frames missing)"
        )
    return np.stack([got[k] for k in want])
