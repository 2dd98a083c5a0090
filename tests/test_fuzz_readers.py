"""Property-based fuzzing of every reader: nothing escapes but the toolkit's own errors.

Random bytes, and valid files mutated by deleting, duplicating or inserting tokens,
inserting garbage and truncating. A reader either returns data or raises a CassiError.
"""

import warnings
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cassi_fit.dataset import load_recording
from cassi_fit.errors import CassiError
from cassi_fit.headmeasures import read_headmeasures
from cassi_fit.outlines import read_outline
from cassi_fit.quality import quality_report
from cassi_fit.txy import read_txy

FIXTURES = Path(__file__).parent / "fixtures"
SETTINGS = settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def _read_pellets(p):
    track = read_txy(p)
    assert track.positions.shape == (track.n_frames, 8, 2)
    assert np.array_equal(np.isnan(track.positions), ~track.valid)
    quality_report(track)  # the report must cope with whatever a reader accepts


def _read_palate(p):
    pts = read_outline(p)
    assert pts.ndim == 2 and pts.shape[1] == 2 and len(pts) >= 2 and np.isfinite(pts).all()


def _read_head(p):
    for m in read_headmeasures(p).values():
        assert all(np.isfinite(v) for v in m.to_dict().values())


READERS = {
    "sample.txy": _read_pellets,
    "PAL.DAT": _read_palate,
    "PHA.DAT": lambda p: read_outline(p, kind="pharynx"),
    "Headmeasures.txt": _read_head,
}
GARBAGE = st.sampled_from(
    [b"", b"\t", b" ", b"\r\n", b"\n", b"1000000", b"-", b"+7", b"1e3", b"nan", b"inf", b"#",
     b"0x1F", b"\xef\xbb\xbf", b"\xff", b"\x00", b"12.5", b"99999999999999999999999", b"subject",
     b"face_width", b"\xc3\xa9", b"\x0b", b"\r"]
)  # fmt: skip


def _check(tmp_path, name, data: bytes):
    p = tmp_path / name
    p.write_bytes(data)
    try:
        READERS[name](p)
    except CassiError:
        pass


@SETTINGS
@given(name=st.sampled_from(sorted(READERS)), data=st.binary(max_size=400))
def test_random_bytes(tmp_path, name, data):
    _check(tmp_path, name, data)


@st.composite
def mutated(draw):
    name = draw(st.sampled_from(sorted(READERS)))
    tokens = (FIXTURES / name).read_bytes().replace(b"\t", b" \t ").split(b" ")
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["delete", "duplicate", "insert", "replace", "truncate"]))
        i = draw(st.integers(0, max(len(tokens) - 1, 0)))
        if op == "delete" and tokens:
            del tokens[i]
        elif op == "duplicate" and tokens:
            tokens.insert(i, tokens[i])
        elif op == "insert":
            tokens.insert(i, draw(GARBAGE))
        elif op == "replace" and tokens:
            tokens[i] = draw(GARBAGE)
        elif op == "truncate":
            tokens = tokens[:i]
    return name, b" ".join(tokens)


@SETTINGS
@given(case=mutated())
def test_mutated_valid_files(tmp_path, case):
    _check(tmp_path, *case)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.binary(max_size=200), pal=st.binary(max_size=100))
def test_load_recording_with_fuzzed_palate(tmp_path, data, pal):
    subject = tmp_path / "S01"
    subject.mkdir(exist_ok=True)
    (subject / "tp001.txy").write_bytes((FIXTURES / "sample.txy").read_bytes() + data)
    (subject / "PAL.DAT").write_bytes(pal)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            load_recording(subject / "tp001.txy")
        except CassiError:
            pass
