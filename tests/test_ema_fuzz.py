"""Property-based fuzzing of the articulograph readers and of load_recording on them: a
damaged EST, .pos, Wave or TOML file either loads or raises the toolkit's own error,
never anything else and never a silent NaN where a value is marked tracked."""

import warnings
from pathlib import Path

import numpy as np
from ema_files import mocha_binary
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cassi_fit.dataset import load_recording
from cassi_fit.ema.sensor_map import read_sensor_map
from cassi_fit.errors import CassiError

FIXTURES = Path(__file__).parent / "fixtures" / "ema"
SETTINGS = settings(max_examples=40, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])
AG501 = (b"AG50xDATA_V002\n00000070\nNumberOfChannels=16\nSamplingFrequencyHz=250\n\x00\x1a"
         + np.arange(16 * 7 * 3, dtype="<f4").tobytes())
SOURCES = {
    "mocha.ema": mocha_binary(6),
    "mocha_ascii.txt": (FIXTURES / "mocha_ascii.txt").read_bytes(),
    "wave.tsv": (FIXTURES / "wave_export.tsv").read_bytes(),
    "rec.pos": AG501,
}


def _mutate(data: bytes, cut: int, at: int, insert: bytes) -> bytes:
    at = at % (len(data) + 1)
    return (data[:at] + insert + data[at + cut:])[: max(1, len(data) - cut // 2)]


@SETTINGS
@given(name=st.sampled_from(sorted(SOURCES)), cut=st.integers(0, 40), at=st.integers(0, 4000),
       insert=st.binary(max_size=12))
def test_damaged_files_load_or_raise_a_toolkit_error(tmp_path, name, cut, at, insert):
    path = tmp_path / name
    path.write_bytes(_mutate(SOURCES[name], cut, at, insert))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = load_recording(path, sensor_map=FIXTURES / "lab_sensors.toml"
                                 if name == "rec.pos" else None)
    except CassiError:
        return
    track = rec.track
    assert np.array_equal(np.isnan(track.positions), ~track.valid)
    assert np.array_equal(np.isnan(track.extra_positions), ~track.extra_valid)


@SETTINGS
@given(cut=st.integers(0, 30), at=st.integers(0, 400), insert=st.binary(max_size=8))
def test_damaged_sensor_maps_read_or_raise_a_toolkit_error(tmp_path, cut, at, insert):
    path = tmp_path / "map.toml"
    path.write_bytes(_mutate((FIXTURES / "lab_sensors.toml").read_bytes(), cut, at, insert))
    try:
        read_sensor_map(path)
    except CassiError:
        pass
