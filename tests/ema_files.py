"""Articulograph files built by hand from the formats' documentation, for the EMA tests:
MOCHA-TIMIT's EST Track layout (its 20 channels in its order, hundredths of a mm, x toward
the back of the head), written with struct, independently of the toolkit's writers."""

import struct

# MOCHA-TIMIT's 20 channels, as a real file's header names them (v_x / v_y with a space).
MOCHA_CHANNELS = ["ui_x", "li_x", "ul_x", "ll_x", "tt_x", "ui_y", "li_y", "ul_y", "ll_y", "tt_y",
                  "tb_x", "td_x", "v_x ", "****", "bn_x", "tb_y", "td_y", "v_y ", "****", "bn_y"]
# Toolkit-frame positions (mm, x forward) of a made-up speaker; MOCHA stores -x, in 1/100 mm.
TOOLKIT_MM = {"ui": (0.0, 0.0), "li": (-1.5, -8.5), "ul": (10.5, 8.5), "ll": (9.5, -13.0),
              "tt": (-9.0, -3.5), "tb": (-21.0, 0.0), "td": (-38.0, 2.5), "v": (-55.0, -1.5),
              "bn": (15.0, 61.0)}


def mocha_values(frame: int) -> list[float]:
    """One frame's 20 channel values as MOCHA writes them (x toward the back, 1/100 mm);
    the lower lip moves down 0.1 mm a frame."""
    out = []
    for name in MOCHA_CHANNELS:
        if name == "****":
            out.append(0.0)
            continue
        sensor, axis = name.strip().split("_")
        x, y = TOOLKIT_MM[sensor]
        if sensor == "ll":
            y -= 0.1 * frame
        out.append(-x * 100 if axis == "x" else y * 100)
    return out


def mocha_header(n: int, data_type: str = "binary", order: str = "01",
                 channels=MOCHA_CHANNELS, n_channels=None) -> bytes:
    lines = ["EST_File Track", f"DataType {data_type}", f"NumFrames {n}", f"ByteOrder {order}",
             f"NumChannels {len(channels) if n_channels is None else n_channels}",
             "EqualSpace 1", "BreaksPresent true", "CommentChar ;", ""]
    lines += [f"Channel_{i} {c}" for i, c in enumerate(channels)]
    lines.append("EST_Header_End")
    return ("\n".join(lines) + "\n").encode("ascii")


def mocha_binary(n: int = 6, order: str = "01", **kw) -> bytes:
    fmt = ("<" if order == "01" else ">") + "22f"
    body = b"".join(struct.pack(fmt, 0.002 * i, 1.0, *mocha_values(i)) for i in range(n))
    return mocha_header(n, order=order, **kw) + body
