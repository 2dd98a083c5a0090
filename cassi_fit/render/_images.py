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


#: The caption band's shading of a byte: 2/3 toward dark grey.
_DARKEN = (np.arange(256, dtype=np.uint16) * 85 // 255 + 13).astype(np.uint8)


def add_caption(image: UInt8[Any, "h w 3"], text: object, *,
                in_place: bool = False) -> UInt8[np.ndarray, "h w 3"]:
    """A copy of ``image`` ((H,W,3) uint8) with ``text`` in white on a dark band at the
    bottom (``in_place``: ``image`` itself, a C-contiguous uint8 array, drawn into).

    Only the band is touched. The text is laid out and rasterised once (Pillow's
    ``getmask2``, as ``ImageDraw.text`` does) and blended in numpy as Pillow blends it:
    the same bytes as ``ImageDraw.multiline_text`` over ``multiline_textbbox``'s band,
    at a third of the cost (a caption on every frame of a video).
    """
    if in_place and isinstance(image, np.ndarray) and image.dtype == np.uint8:
        out = image
    else:
        out = np.array(image, dtype=np.uint8, copy=True)
    if out.ndim != 3 or out.shape[2] != 3:
        raise CassiError(f"add_caption: an image must be (H, W, 3) uint8, got {out.shape}")
    height = out.shape[0]
    text = str(text)
    font = _font(max(10, height // 32))
    pad = max(2, height // 120)
    if "\n" in text or "\r" in text:  # several lines: Pillow's own layout
        return _caption_lines(out, text, font, pad)
    mask, _ = _text_mask(text, font)
    band_top = max(0, height - mask.shape[0] - 2 * pad)
    band = out[band_top:]
    np.take(_DARKEN, band, out=band)  # 2/3 toward dark grey
    # the mask's box is the text's bounding box, drawn at (pad, pad) in the band; white
    # ink blended as Pillow's fill_mask_L: (in * (255 - m) + 255 * m + 128) / 255, rounded
    # as its DIV255
    rows = band[pad:pad + mask.shape[0], pad:pad + mask.shape[1]]
    m = mask[: rows.shape[0], : rows.shape[1], None].astype(np.uint32)
    tmp = rows * (255 - m) + 255 * m + 128
    rows[...] = (((tmp >> 8) + tmp) >> 8).astype(np.uint8)
    return out


def _text_mask(text: str, font) -> tuple[np.ndarray, tuple[int, int]]:
    """(coverage (h, w) uint8, offset) of one line of ``text``: the anti-aliased mask
    ``ImageDraw.text`` pastes for it (``font.getmask2(text, "L")``, its box the text's
    bounding box ``font.getbbox``; offset its top-left corner from the anchor)."""
    from PIL import Image

    core, offset = font.getmask2(text, "L")
    return np.asarray(Image.Image()._new(core)), offset


def _caption_lines(out: np.ndarray, text: str, font, pad: int) -> np.ndarray:
    """:func:`add_caption` of a text of several lines, by Pillow's multiline layout."""
    from PIL import Image, ImageDraw

    height = out.shape[0]
    left, top, right, bottom = ImageDraw.Draw(Image.new("L", (1, 1))).multiline_textbbox(
        (0, 0), text, font=font
    )
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
