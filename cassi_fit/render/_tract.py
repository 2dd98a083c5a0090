"""The ``tract`` view: a frame's vocal tract as a speech scientist plots it, drawn in 2D
into its cell (Pillow, no OpenGL) beside the face.

Top half: the area function, area (cm^2) against the distance from the glottis (cm), as
steps, one per tube section, the lips at the right. Bottom half: the tube's transfer
function (dB) from 0 to 5 kHz with the model's F1-F3 as vertical lines and, where the
sound was measured reliably at that frame, the measured F1-F3 as red ticks on the
frequency axis. The numbers come from ``acoustics.tract_panels`` (the same area function
and lossy tube as ``cassi acoustics``); the renderer only draws them. Fixed axes (0-20 cm,
0-8 cm^2 unless the tract is wider, 0-5 kHz, a 60 dB span below the frame's peak) so that
frames compare by eye.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..options import TRACT_VIEW as TRACT_VIEW

LENGTH_CM = 20.0
AREA_CM2 = 8.0
SPAN_DB = 60.0
_INK = (40, 40, 40)
_GRID = (200, 200, 200)
_AREA = (60, 110, 170)
_MODEL = (30, 120, 60)
_MEASURED = (200, 40, 40)


def draw_tract(image: np.ndarray, box: tuple[int, int, int, int],
               panel: Mapping[str, Any] | None) -> None:
    """Draw one frame's ``panel`` into ``image[top:bottom, left:right]`` (``box``: left,
    top, right, bottom in pixels), in place. ``panel``: ``lengths_mm (n,)`` and
    ``areas_mm2 (n,)`` glottis first, ``frequency_hz (k,)`` and ``gain_db (k,)``,
    ``model_hz (3,)``, ``measured_hz (3,)`` (NaN where not measured), optionally
    ``tract`` (which vocal tract, in words; written in the area plot). None: the cell says
    that there is no tract for this frame."""
    from PIL import Image, ImageDraw

    from ._images import _font

    left, top, right, bottom = box
    w, h = right - left, bottom - top
    if w < 16 or h < 16:
        return
    cell = Image.fromarray(image[top:bottom, left:right])
    draw = ImageDraw.Draw(cell)
    font = _font(max(9, h // 26))
    if panel is None:
        draw.text((w // 20, h // 2), "no vocal tract for this frame", font=font, fill=_INK)
        image[top:bottom, left:right] = np.asarray(cell)
        return
    pad_l, pad_r = max(24, w // 9), max(6, w // 40)
    # below each plot: its tick labels and axis title; at the image's foot, the caption band
    below = 2 * font.size + 8
    caption = max(16, image.shape[0] // 32 + 12) if bottom >= image.shape[0] - 2 else 0
    half = (h - caption) // 2
    _area_plot(draw, font, (pad_l, 6, w - pad_r, half - below), panel)
    if panel.get("tract_label"):  # which tract: the adult norms or the subject's fitted one
        draw.text((pad_l + 3, 8), str(panel["tract_label"]), font=font, fill=_INK)
    _spectrum_plot(draw, font, (pad_l, half + 6, w - pad_r, h - caption - below), panel)
    image[top:bottom, left:right] = np.asarray(cell)


def _axes(draw, box, x_ticks, y_ticks, font, x_label, y_label):
    """The frame, grid lines at the ticks ((value in 0..1, text) pairs) and labels."""
    x0, y0, x1, y1 = box
    for f, text in x_ticks:
        x = x0 + f * (x1 - x0)
        draw.line([(x, y0), (x, y1)], fill=_GRID)
        draw.text((x, y1 + 2), text, font=font, fill=_INK, anchor="ma")
    for f, text in y_ticks:
        y = y1 - f * (y1 - y0)
        draw.line([(x0, y), (x1, y)], fill=_GRID)
        draw.text((x0 - 3, y), text, font=font, fill=_INK, anchor="rm")
    draw.rectangle([x0, y0, x1, y1], outline=_INK)
    draw.text((x1, y0 + 2), y_label, font=font, fill=_INK, anchor="ra")
    draw.text(((x0 + x1) / 2, y1 + 2 + font.size), x_label, font=font, fill=_INK, anchor="ma")


def _area_plot(draw, font, box, panel) -> None:
    x0, y0, x1, y1 = box
    lengths = np.asarray(panel["lengths_mm"], float) / 10.0
    areas = np.asarray(panel["areas_mm2"], float) / 100.0
    top_cm2 = max(AREA_CM2, float(np.nanmax(areas, initial=0.0)) * 1.05)
    span_cm = max(LENGTH_CM, float(np.nansum(lengths)))
    _axes(draw, box, [(c / span_cm, f"{c:g}") for c in range(0, int(span_cm) + 1, 5)],
          [(a / top_cm2, f"{a:g}") for a in range(0, int(top_cm2) + 1, 2)], font,
          "cm from the glottis", "area, cm^2")  # fmt: skip
    ends = np.concatenate([[0.0], np.cumsum(lengths)])
    points = []
    for k, a in enumerate(areas):
        if not np.isfinite(a):
            continue
        y = y1 - min(a / top_cm2, 1.0) * (y1 - y0)
        xa = x0 + ends[k] / span_cm * (x1 - x0)
        xb = x0 + ends[k + 1] / span_cm * (x1 - x0)
        draw.rectangle([xa, y, xb, y1], fill=(190, 210, 232))
        points += [(xa, y), (xb, y)]
    if len(points) > 1:
        draw.line(points, fill=_AREA, width=2)


def _spectrum_plot(draw, font, box, panel) -> None:
    x0, y0, x1, y1 = box
    freq = np.asarray(panel["frequency_hz"], float)
    gain = np.asarray(panel["gain_db"], float)
    f_top = float(freq[-1]) if len(freq) else 5000.0
    _axes(draw, box, [(f / f_top, f"{f / 1000:g}") for f in range(0, int(f_top) + 1, 1000)],
          [], font, "kHz", "tube gain, dB")  # fmt: skip
    ok = np.isfinite(gain)
    if ok.sum() > 1:
        peak = float(gain[ok].max())
        level = np.clip((gain - (peak - SPAN_DB)) / SPAN_DB, 0.0, 1.0)
        xs = x0 + freq / f_top * (x1 - x0)
        ys = y1 - level * (y1 - y0)
        draw.line([(float(x), float(y)) for x, y, g in zip(xs, ys, ok, strict=True) if g],
                  fill=_INK, width=2)
    for q, f in enumerate(np.asarray(panel["model_hz"], float)[:3]):
        if np.isfinite(f) and 0 < f < f_top:
            x = x0 + f / f_top * (x1 - x0)
            draw.line([(x, y0), (x, y1)], fill=_MODEL, width=1)
            draw.text((x + 2, y0 + 1), f"F{q + 1}", font=font, fill=_MODEL)
    measured = np.asarray(panel.get("measured_hz", ()), float)[:3]
    if np.isfinite(measured).any():
        draw.text((x1 - 3, y1 - 3), "red: the sound's", font=font, fill=_MEASURED, anchor="rd")
    for f in measured:
        if np.isfinite(f) and 0 < f < f_top:
            x = x0 + f / f_top * (x1 - x0)
            draw.polygon([(x, y1), (x - 4, y1 - 9), (x + 4, y1 - 9)], fill=_MEASURED)
