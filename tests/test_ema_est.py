"""EST Track reader (cassi_fit.ema.est) on bytes written by hand from the format's
documentation: MOCHA-TIMIT's header and channel order, both byte orders, ascii, breaks,
NaN values, and every refusal (truncated body, a header that lies, a missing channel)."""

import struct
from pathlib import Path

import numpy as np
import pytest
from ema_files import MOCHA_CHANNELS, mocha_binary, mocha_header, mocha_values

from cassi_fit.ema.detect import detect_format
from cassi_fit.ema.est import read_est
from cassi_fit.errors import DataFormatError

FIXTURES = Path(__file__).parent / "fixtures" / "ema"


@pytest.mark.parametrize("order", ["01", "10"])
def test_binary_mocha_in_either_byte_order(tmp_path, order):
    path = tmp_path / "fsew0_001.ema"
    path.write_bytes(mocha_binary(6, order))
    raw = read_est(path)
    assert raw.names == ("ui", "li", "ul", "ll", "tt", "tb", "td", "v", "bn")  # no '****'
    assert raw.frame == "mocha" and raw.dims == 2 and raw.rate_hz == 500.0
    np.testing.assert_allclose(raw.times, 0.002 * np.arange(6), rtol=1e-6)
    ul = raw.sensor("ul")
    np.testing.assert_allclose(ul[0], [-10.5, 8.5], atol=1e-5)  # mm, still x toward the back
    np.testing.assert_allclose(raw.sensor("ll")[:, 1], -13.0 - 0.1 * np.arange(6), atol=1e-5)
    assert any("****" in n for n in raw.notes)


def test_ascii_with_crlf_breaks_and_nan(tmp_path):
    raw = read_est(FIXTURES / "mocha_ascii.txt")  # hand-written, CRLF line ends
    assert raw.frame == "mocha" and raw.positions.shape == (4, 9, 2)
    np.testing.assert_allclose(raw.sensor("tt")[0], [9.0, -3.5])  # the file's axes (x back)
    assert np.isnan(raw.sensor("tt")[2, 1]) and not np.isnan(raw.sensor("tt")[2, 0])
    assert np.isnan(raw.positions[3]).all()  # break flag 0: the whole frame untracked


def test_detected_by_content_whatever_the_name(tmp_path):
    for name in ("utterance.txt", "noext", "x.ema"):
        path = tmp_path / name
        path.write_bytes(mocha_binary(3))
        assert detect_format(path) == "est"


def test_a_three_d_file_with_orientation_channels(tmp_path):
    channels = ["T1_px", "T1_py", "T1_pz", "T1_ox", "T1_oy", "T1_oz", "UL_px", "UL_py", "UL_pz"]
    lines = ["EST_File Track", "DataType ascii", "NumFrames 2", f"NumChannels {len(channels)}",
             "BreaksPresent false", "name mngu0_s1_0001"]
    lines += [f"Channel_{i} {c}" for i, c in enumerate(channels)] + ["EST_Header_End"]
    body = ["0.000 1 2 3 0.1 0.2 0.3 7 8 9", "0.005 1.5 2 3 0.1 0.2 0.3 7 8 NaN"]
    path = tmp_path / "mngu0_s1_0001.ema"
    path.write_text("\n".join(lines + body) + "\n")
    raw = read_est(path)
    assert raw.names == ("T1", "UL") and raw.dims == 3 and raw.frame is None
    np.testing.assert_allclose(raw.sensor("T1")[1], [1.5, 2, 3])
    assert np.isnan(raw.sensor("UL")[1, 2])
    np.testing.assert_allclose(raw.orientation[0, 0], [0.1, 0.2, 0.3])
    assert raw.rate_hz == 200.0


@pytest.mark.parametrize("damage, message", [
    (lambda b: b[:-5], "truncated"),
    (lambda b: b.replace(b"NumFrames 6", b"NumFrames 7"), "NumFrames 7"),
    (lambda b: b.replace(b"NumChannels 20", b"NumChannels 21"), "NumChannels 21"),
    (lambda b: b.replace(b"EST_Header_End\n", b""), "EST_Header_End"),
    (lambda b: b.replace(b"ByteOrder 01", b"ByteOrder 99"), "ByteOrder"),
    (lambda b: b.replace(b"EST_File Track", b"EST_File Wave "), "Wave"),
    (lambda b: b.replace(b"NumFrames 6", b"NumFrames six"), "whole number"),
])
def test_hostile_binary_headers(tmp_path, damage, message):
    path = tmp_path / "bad.ema"
    path.write_bytes(damage(mocha_binary(6)))
    with pytest.raises(DataFormatError) as err:
        read_est(path)
    assert str(path) in str(err.value)
    if message:
        assert message in str(err.value)


def test_truncated_body_names_the_byte_offset(tmp_path):
    data = mocha_binary(6)
    path = tmp_path / "cut.ema"
    path.write_bytes(data[:-3])
    with pytest.raises(DataFormatError, match="byte offset") as err:
        read_est(path)
    offset = int(str(err.value).split("byte offset ")[1].rstrip(")"))
    assert offset == len(data) - 88  # the last complete frame (22 float32) ends there


def test_a_missing_channel_is_refused_never_shifted(tmp_path):
    channels = [c for c in MOCHA_CHANNELS if c != "tb_y"]
    n = 2
    body = b"".join(struct.pack("<21f", 0.002 * i, 1.0, *[v for c, v in zip(
        MOCHA_CHANNELS, mocha_values(i), strict=True) if c != "tb_y"]) for i in range(n))
    path = tmp_path / "missing.ema"
    path.write_bytes(mocha_header(n, channels=channels) + body)
    with pytest.raises(DataFormatError, match="'tb' has no y channel"):
        read_est(path)


def test_ascii_errors_name_the_line(tmp_path):
    text = (FIXTURES / "mocha_ascii.txt").read_text()
    lines = text.splitlines()
    bad = lines[:-2] + [lines[-2].replace("0.004 1 0", "0.004 1 zero"), lines[-1]]
    path = tmp_path / "bad.txt"
    path.write_text("\n".join(bad) + "\n")
    with pytest.raises(DataFormatError, match=r"bad\.txt:32: not a number: 'zero'"):
        read_est(path)
    short = lines[:-1] + [" ".join(lines[-1].split()[:-1])]
    path.write_text("\n".join(short) + "\n")
    with pytest.raises(DataFormatError, match=r":33: expected 22 values"):
        read_est(path)
    backwards = lines[:-1] + [lines[-1].replace("0.006 0", "0.001 0")]
    path.write_text("\n".join(backwards) + "\n")
    with pytest.raises(DataFormatError, match=r":33: time 0.001000 s does not increase"):
        read_est(path)
