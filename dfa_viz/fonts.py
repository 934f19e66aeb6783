"""The one font the pictures the clients draw with Pillow use (the page's frames and
captions, the study's familiarisation pictures)."""

from __future__ import annotations

from pathlib import Path

from PIL import ImageFont


def font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """DejaVu Sans of `size` pixels (matplotlib ships it: it has ✓ and ✗), else Pillow's own
    font."""
    import matplotlib

    path = Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"
    return ImageFont.truetype(str(path), size) if path.exists() else ImageFont.load_default(size)
