"""Images for the page: crisp upscaled frames, captions, side-by-side strips, click markers.

Gridworld frames are tiny (36x36); the browser would blur them, so they are upscaled here
with nearest-neighbour repetition and sent as PNG.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw

from dfa_viz.fonts import font

FRAME_PX = 216  # target width of one upscaled frame in the compare strip
CANVAS_PX = 432  # target width of the clickable demonstration canvas
CAPTION_PX = 24
GAP_PX = 6
BACKGROUND = (246, 247, 249)
INK = (33, 37, 41)
MUTED = (120, 124, 130)


_FONT = font(14)
_SMALL = font(12)


def scale_for(frame_shape: Sequence[int], target_px: int = FRAME_PX) -> int:
    """Integer upscale factor that brings a frame of (H, W, 3) near target_px wide."""
    return max(1, round(target_px / frame_shape[1]))


def upscale(frame: np.ndarray, k: int) -> np.ndarray:
    """uint8 (H, W, 3) -> uint8 (k*H, k*W, 3), each pixel a k x k block."""
    assert frame.dtype == np.uint8 and frame.ndim == 3, (
        f"expected uint8 (H, W, 3), got {frame.shape}"
    )
    return np.repeat(np.repeat(frame, k, axis=0), k, axis=1)


def placeholder(shape: tuple[int, int], text: str) -> np.ndarray:
    """A grey tile of (H, W) with centred, wrapped text: uint8 (H, W, 3)."""
    h, w = shape
    img = Image.new("RGB", (w, h), (215, 218, 222))
    draw = ImageDraw.Draw(img)
    words, lines, cur = text.split(), [], ""
    for word in words:
        trial = f"{cur} {word}".strip()
        if draw.textlength(trial, font=_SMALL) > w - 16 and cur:
            lines.append(cur)
            cur = word
        else:
            cur = trial
    lines.append(cur)
    y = h / 2 - 8 * len(lines)
    for line in lines:
        draw.text((w / 2, y), line, fill=INK, font=_SMALL, anchor="ma")
        y += 16
    return np.asarray(img)


def _caption(width: int, title: str, colour: tuple[int, int, int]) -> np.ndarray:
    img = Image.new("RGB", (width, CAPTION_PX), BACKGROUND)
    draw = ImageDraw.Draw(img)
    draw.rectangle((0, CAPTION_PX - 3, width, CAPTION_PX), fill=colour)
    draw.text((width / 2, 3), title, fill=INK, font=_FONT, anchor="ma")
    return np.asarray(img)


def strip(
    columns: Sequence[tuple[str, np.ndarray | None, str, tuple[int, int, int]]],
    *,
    frame_shape: tuple[int, int, int],
    footer: str = "",
) -> np.ndarray:
    """Frames side by side under captions: uint8 (H', W', 3).

    columns: (title, frame uint8 (H, W, 3) or None, text shown when None, caption colour).
    """
    k = scale_for(frame_shape)
    h, w = frame_shape[0] * k, frame_shape[1] * k
    tiles = []
    for title, frame, missing, colour in columns:
        body = upscale(frame, k) if frame is not None else placeholder((h, w), missing)
        tiles.append(np.concatenate([_caption(w, title, colour), body], axis=0))
    gap = np.full((tiles[0].shape[0], GAP_PX, 3), BACKGROUND, np.uint8)
    parts: list[np.ndarray] = []
    for i, t in enumerate(tiles):
        parts += [gap, t] if i else [t]
    out = np.concatenate(parts, axis=1)
    if footer:
        img = Image.new("RGB", (out.shape[1], 20), BACKGROUND)
        ImageDraw.Draw(img).text((4, 3), footer, fill=MUTED, font=_SMALL)
        out = np.concatenate([out, np.asarray(img)], axis=0)
    return np.ascontiguousarray(out)


def frame_at(traj, step: int) -> np.ndarray | None:
    """The trajectory's observation at `step` (its last one past its end); None without one."""
    if traj is None:
        return None
    return traj.observations[min(step, len(traj.observations) - 1)]


def mark_points(
    image: np.ndarray,
    points_uv: Sequence[tuple[float, float]],
    *,
    start_uv: tuple[float, float] | None = None,
    colours: Sequence[tuple[int, int, int]] = ((255, 255, 255),),
    labels: Sequence[str] = (),
    line: bool = True,
) -> np.ndarray:
    """Draw clicked points (u, v in [0, 1], v down) on an image, joined from `start_uv`."""
    img = Image.fromarray(image)
    draw = ImageDraw.Draw(img)
    h, w = image.shape[:2]
    px = [(u * w, v * h) for u, v in points_uv]
    if line and px:
        path = ([(start_uv[0] * w, start_uv[1] * h)] if start_uv else []) + px
        if len(path) > 1:
            draw.line(path, fill=(255, 255, 255), width=3)
            draw.line(path, fill=(255, 140, 0), width=1)
    r = max(4, w // 60)
    for i, (x, y) in enumerate(px):
        c = colours[min(i, len(colours) - 1)]
        draw.ellipse((x - r, y - r, x + r, y + r), fill=c, outline=(0, 0, 0), width=2)
        if i < len(labels):
            draw.text((x + r + 2, y - r), labels[i], fill=(255, 255, 255), font=_FONT)
    return np.asarray(img)


def mark_pick_place(world, frame: np.ndarray, action: np.ndarray, colour) -> np.ndarray:
    """A pick-and-place action (pick x, y, place x, y in the world's coordinates) drawn on the
    frame it was taken from: the pick point in the rollout's colour, a line to the place point
    in white (as the recording draws it)."""
    x0, x1, y0, y1 = world.image_extent
    a = np.asarray(action, np.float64).reshape(-1)[:4]
    uv = [((x - x0) / (x1 - x0), (y1 - y) / (y1 - y0)) for x, y in (a[:2], a[2:4])]
    return mark_points(frame, uv, colours=(colour, (255, 255, 255)))
