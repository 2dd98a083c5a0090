"""Images: a caption band drawn onto a rendered frame, and PNG files written safely."""

from __future__ import annotations

import functools
import io
import os
from pathlib import Path
from typing import Any

import numpy as np
from jaxtyping import UInt8

from .._io import atomic_write
from ..errors import CassiError


@functools.lru_cache(maxsize=8)  # a font at one size, not a computation: kept
def _font(size: int):
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


def add_caption(image: UInt8[Any, "h w 3"], text: object) -> UInt8[np.ndarray, "h w 3"]:
    """A copy of ``image`` ((H,W,3) uint8) with ``text`` in white on a dark band at the bottom.

    Only the band is touched (about 1 ms at 640x480, so a caption on every frame is cheap).
    """
    from PIL import Image, ImageDraw

    out = np.array(image, dtype=np.uint8, copy=True)
    if out.ndim != 3 or out.shape[2] != 3:
        raise CassiError(f"add_caption: an image must be (H, W, 3) uint8, got {out.shape}")
    height = out.shape[0]
    text = str(text)
    font = _font(max(10, height // 32))
    left, top, right, bottom = ImageDraw.Draw(Image.new("L", (1, 1))).multiline_textbbox(
        (0, 0), text, font=font
    )
    pad = max(2, height // 120)
    band_top = max(0, height - (bottom - top) - 2 * pad)
    band = out[band_top:].astype(np.uint16) * 85 // 255 + 13  # 2/3 toward dark grey
    pil = Image.fromarray(band.astype(np.uint8))
    ImageDraw.Draw(pil).multiline_text((pad - left, pad - top), text, font=font, fill=(255,) * 3)
    out[band_top:] = np.asarray(pil)
    return out


def save_png(
    path: str | os.PathLike, image: UInt8[Any, "h w c"], *, overwrite: bool = True
) -> Path:
    """Write an (H,W,3) or (H,W,4) uint8 image as PNG, atomically, with the user's normal
    mode; returns the path. Never replaces an input or a recording's data file."""
    from PIL import Image

    array = np.asarray(image)
    if array.dtype != np.uint8 or array.ndim != 3 or array.shape[2] not in (3, 4):
        raise CassiError(
            f"{path}: an image must be (H, W, 3|4) uint8, got {array.shape} {array.dtype}"
        )
    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, format="PNG")
    return atomic_write(path, buffer.getvalue(), overwrite=overwrite)
