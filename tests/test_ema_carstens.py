"""Carstens .pos reader (cassi_fit.ema.carstens) on bytes built by hand from the format's
documentation (AG501: the text header Carstens writes, then 7 little-endian float32 per
channel and frame; AG500: no header, 12 channels at 200 Hz), and its refusals."""

import struct

import numpy as np
import pytest

from cassi_fit.ema.carstens import read_pos
from cassi_fit.ema.detect import detect_format
from cassi_fit.errors import DataFormatError

# The header exactly as an AG501 writes it for 16 channels at 250 Hz (70 bytes).
AG501_HEADER = (b"AG50xDATA_V002\n00000070\nNumberOfChannels=16\nSamplingFrequencyHz=250\n"
                b"\x00\x1a")


def value(frame: int, channel: int, field: int) -> float:
    """A distinct number for every value: x, y, z in mm, then angles, rms, extra."""
    return 1000.0 * frame + 10.0 * channel + field + 0.5


def samples(n_frames: int, n_channels: int) -> bytes:
    return b"".join(struct.pack("<7f", *[value(f, c, k) for k in range(7)])
                    for f in range(n_frames) for c in range(n_channels))


def test_ag501_header_and_samples(tmp_path):
    assert len(AG501_HEADER) == 70
    path = tmp_path / "0001.pos"
    path.write_bytes(AG501_HEADER + samples(3, 16))
    raw = read_pos(path)
    assert raw.format == "ag501" and raw.rate_hz == 250.0 and raw.dims == 3
    assert raw.names == tuple(f"Ch{i}" for i in range(1, 17))
    np.testing.assert_allclose(raw.times, [0.0, 0.004, 0.008])
    np.testing.assert_allclose(raw.sensor("Ch5")[2], [value(2, 4, k) for k in range(3)])
    np.testing.assert_allclose(raw.orientation[1, 15], [value(1, 15, k) for k in range(3, 7)])
    assert detect_format(path) == "ag501"


def test_ag501_header_with_crlf_and_an_extra_key(tmp_path):
    text = b"AG50xDATA_V003\r\n00000090\r\nNumberOfChannels=2\r\nSamplingFrequencyHz=1250\r\n"
    text += b"Operator=JW\r\n"
    header = text + b"\x00" * (90 - len(text) - 1) + b"\x1a"
    path = tmp_path / "crlf.pos"
    path.write_bytes(header + samples(2, 2))
    raw = read_pos(path)
    assert raw.rate_hz == 1250.0 and raw.positions.shape == (2, 2, 3)
    np.testing.assert_allclose(raw.sensor("Ch2")[1], [value(1, 1, k) for k in range(3)])


def test_headerless_ag500(tmp_path):
    path = tmp_path / "0001.pos"
    path.write_bytes(samples(4, 12))
    assert detect_format(path) == "ag500"
    raw = read_pos(path)
    assert raw.format == "ag500" and raw.rate_hz == 200.0 and raw.positions.shape == (4, 12, 3)
    np.testing.assert_allclose(raw.sensor("Ch12")[3], [value(3, 11, k) for k in range(3)])


def test_nan_and_zero_channels_are_untracked(tmp_path):
    data = bytearray(AG501_HEADER.replace(b"=16", b"=02").replace(b"00000070", b"00000070")
                     + samples(2, 2))
    # frame 0, channel 1: x is NaN; frame 1, channel 0: an unused all-zero position
    struct.pack_into("<f", data, 70 + 28, float("nan"))
    struct.pack_into("<3f", data, 70 + 56, 0.0, 0.0, 0.0)
    path = tmp_path / "lost.pos"
    path.write_bytes(bytes(data))
    raw = read_pos(path)
    assert np.isnan(raw.sensor("Ch2")[0, 0]) and np.isfinite(raw.sensor("Ch2")[0, 1])
    assert np.isnan(raw.sensor("Ch1")[1]).all()
    assert np.isfinite(raw.sensor("Ch1")[0]).all()


@pytest.mark.parametrize("data, message", [
    (AG501_HEADER + samples(2, 16)[:-6], "byte offset 518"),
    (AG501_HEADER.replace(b"00000070", b"00009999") + samples(1, 16), "more than the file"),
    (AG501_HEADER.replace(b"00000070", b"000000xx"), "not a number"),
    (AG501_HEADER.replace(b"NumberOfChannels=16", b"NumberOfSensors=16") + samples(1, 16),
     "NumberOfChannels"),
    (AG501_HEADER.replace(b"V002", b"V009") + samples(1, 16), "version"),
    (AG501_HEADER, "no samples"),
    (samples(3, 12)[:-4], "is this a .pos file"),
])
def test_hostile_files(tmp_path, data, message):
    path = tmp_path / "bad.pos"
    path.write_bytes(data)
    with pytest.raises(DataFormatError, match=message) as err:
        read_pos(path)
    assert str(path) in str(err.value)
