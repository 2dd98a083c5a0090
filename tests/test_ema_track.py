"""From articulograph sensors to the pellet track (cassi_fit.ema.track, cassi_fit.ema.arrays,
PelletTrack's extra sensors): MOCHA's axes turned into the toolkit's, 2D axes of unknown
sign decided by the anatomy, the refusals that guard against a wrong guess (units, 3D
device frames without a frame), arrays with a layout, recording_from_array."""

import struct
from pathlib import Path

import numpy as np
import pytest
from ema_files import mocha_binary

from cassi_fit.dataset import recording_from_array
from cassi_fit.ema import RawEma, ema_to_track, read_ema
from cassi_fit.ema.arrays import SPARC_COLUMNS, raw_from_array, read_array
from cassi_fit.ema.sensor_map import SensorMap
from cassi_fit.errors import DataFormatError
from cassi_fit.pellets import PELLET_NAMES
from cassi_fit.txy import PelletTrack

FIXTURES = Path(__file__).parent / "fixtures" / "ema"
# toolkit-frame positions (mm) of a made-up speaker, 2D
SPEAKER = {"TD": (-38.0, 2.5), "TB": (-21.0, 0.0), "TT": (-9.0, -3.5), "LI": (-1.5, -8.5),
           "UL": (10.5, 8.5), "LL": (9.5, -13.0)}


def _role(track, name):
    return track.positions[:, PELLET_NAMES.index(name)]


def test_mocha_ascii_fixture_lands_in_the_toolkit_frame():
    track, report = ema_to_track(read_ema(FIXTURES / "mocha_ascii.txt"))
    ul, ll, t1, mni = (_role(track, r)[0] for r in ("UL", "LL", "T1", "MNI"))
    np.testing.assert_allclose(ul, [10.5, 8.5])  # MOCHA's x toward the back, mirrored
    assert ul[1] > ll[1]  # upper lip above the lower lip
    assert t1[0] < 0 < ul[0] and t1[0] < mni[0]  # the tongue behind the incisors
    assert not track.valid[:, PELLET_NAMES.index("T4")].any()  # three tongue sensors
    assert not track.valid[:, PELLET_NAMES.index("MNM")].any()  # one jaw sensor
    assert not track.valid[2, PELLET_NAMES.index("T1")].any()  # NaN in the file
    assert track.extra_names == ("ui", "v", "bn")
    np.testing.assert_allclose(track.extra("bn")[0], [15.0, 61.0])
    assert report.references == ("ui", "bn") and "MOCHA" in report.frame_source
    assert report.frames_without_references == 1  # the break frame has no references
    assert track.frame_step_s == pytest.approx(0.002)


def _array(flip_x=False, flip_y=False, n=20):
    cols = []
    for name in ("TD", "TB", "TT", "LI", "UL", "LL"):
        x, y = SPEAKER[name]
        cols += [np.full(n, -x if flip_x else x), np.full(n, -y if flip_y else y)]
    out = np.column_stack(cols)
    out[:, 11] -= np.linspace(0, 3, n) * (-1 if flip_y else 1)  # the lower lip opens
    return out


@pytest.mark.parametrize("flip_x, flip_y", [(False, False), (True, False), (True, True)])
def test_unknown_2d_axes_get_their_signs_from_the_anatomy(flip_x, flip_y):
    raw = raw_from_array(_array(flip_x, flip_y), layout="mngu0", rate=200.0)
    track, report = ema_to_track(raw)
    np.testing.assert_allclose(_role(track, "UL")[0], SPEAKER["UL"])
    np.testing.assert_allclose(_role(track, "T3")[0], SPEAKER["TD"])
    assert ("x mirrored" in report.frame_source) == flip_x
    assert ("y mirrored" in report.frame_source) == flip_y
    assert "occlusal plane not given" in report.frame_source


def test_declared_axes_are_used_and_a_wrong_declaration_is_caught():
    raw = raw_from_array(_array(flip_x=True), layout="mngu0", rate=200.0)
    given = SensorMap(anterior="-x", up="+y", origin=(0.0, 0.0), occlusal_plane="declared")
    track, _ = ema_to_track(raw, given)  # the frame given whole: used as it is
    np.testing.assert_allclose(_role(track, "UL")[0], SPEAKER["UL"])
    with pytest.raises(DataFormatError, match="tongue tip T1 in front of the upper lip"):
        ema_to_track(raw, SensorMap(anterior="+x", up="+y"))


def test_wrong_units_are_refused():
    raw = raw_from_array(_array() / 10.0, layout="mngu0", rate=200.0)  # centimetres
    with pytest.raises(DataFormatError, match=r"span 5.\d+ mm, not a head"):
        ema_to_track(raw)
    ok, _ = ema_to_track(raw, SensorMap(scale_mm=10.0))
    np.testing.assert_allclose(_role(ok, "UL")[0], SPEAKER["UL"])


def test_3d_device_coordinates_need_a_frame():
    rng = np.random.default_rng(0)
    pos = rng.normal(scale=30, size=(10, 4, 3)) + 200.0
    raw = RawEma(format="wave", times=np.arange(10) / 100, names=("UL", "LL", "TT", "JAW"),
                 positions=pos, rate_hz=100.0, units="mm", axes="device")
    with pytest.raises(DataFormatError, match="give a bite-plane recording, an upper-incisor"):
        ema_to_track(raw)


def test_sparc_arrays_are_normalised_and_need_their_statistics(tmp_path):
    z = np.random.default_rng(3).normal(size=(25, 12))
    with pytest.raises(DataFormatError, match="normalised, not millimetres"):
        raw_from_array(z, layout="sparc", rate=50.0)
    mean = _array(n=1)[0]
    sd = np.full(12, 0.5)
    rec = recording_from_array(z, layout="sparc", rate=50.0, mean_mm=mean, sd_mm=sd)
    assert rec.sensors.format == "array" and rec.head_is_default and rec.path is None
    np.testing.assert_allclose(_role(rec.track, "UL"), mean[8:10] + 0.5 * z[:, 8:10],
                               atol=1e-9)  # mm = mean + sd * value, axes unchanged
    assert rec.track.frame_step_s == pytest.approx(0.02)
    assert rec.sensors.roles["T3"] == "TD" and rec.sensors.roles["MNI"] == "LI"


def test_array_files(tmp_path):
    values = _array()
    npy = tmp_path / "ema.npy"
    np.save(npy, values)
    raw = read_ema(npy, layout="mngu0", rate=100.0)
    np.testing.assert_allclose(raw.sensor("UL")[0], SPEAKER["UL"])
    npz = tmp_path / "ema.npz"
    np.savez(npz, ema=values, times=np.arange(values.shape[0]) * 0.01)
    assert read_ema(npz, layout="mngu0").rate_hz == 100.0
    csv = tmp_path / "ema.csv"
    header = "time," + ",".join(f"{c[:2]}_{c[2].lower()}" for c in SPARC_COLUMNS)
    rows = [f"{0.02 * i:.2f}," + ",".join(f"{v:g}" for v in row) for i, row in enumerate(values)]
    csv.write_text("\n".join([header] + rows) + "\n")
    raw = read_array(csv)
    assert raw.rate_hz == 50.0 and raw.names == ("TD", "TB", "TT", "LI", "UL", "LL")
    rows[3] = rows[3].replace(",", ",x", 1)
    csv.write_text("\n".join([header] + rows) + "\n")
    with pytest.raises(DataFormatError, match=r"ema\.csv:5: not a number"):
        read_array(csv)
    with pytest.raises(DataFormatError, match="needs its rate"):
        read_ema(npy, layout="mngu0")
    with pytest.raises(DataFormatError, match="the layout has 12 columns"):
        raw_from_array(values[:, :10], layout="mngu0", rate=50.0)
    with pytest.raises(DataFormatError, match="sensor 'UL' has no y column"):
        raw_from_array(values[:, :9], layout=[*SPARC_COLUMNS[:9]], rate=50.0)


def test_pellet_track_extras_default_empty_and_are_checked():
    n = 4
    pos = np.zeros((n, 8, 2))
    track = PelletTrack(times=np.arange(n) * 0.004, positions=pos, valid=np.ones((n, 8, 2), bool))
    assert track.extra_names == () and track.extra_positions.shape == (n, 0, 2)
    assert track.frame_step_s == pytest.approx(0.004)
    with pytest.raises(ValueError, match=r"\(4, 1, 2\) for 1 extra"):
        PelletTrack(times=track.times, positions=pos, valid=track.valid, extra_names=("v",),
                    extra_positions=np.zeros((n, 2, 2)))
    with pytest.raises(ValueError, match="no extra sensor 'x'"):
        track.extra("x")


def test_binary_mocha_file_named_txt_loads_as_a_recording(tmp_path):
    # the example: a MOCHA EST file; here the bytes are built by hand
    path = tmp_path / "fsew0_001.txt"
    path.write_bytes(mocha_binary(8, "10"))
    from cassi_fit.dataset import load_recording

    with pytest.warns(UserWarning):
        rec = load_recording(path)
    assert (rec.subject, rec.task, rec.format) == ("FSEW0", "001", "est")
    ul, ll = _role(rec.track, "UL"), _role(rec.track, "LL")
    assert (ul[:, 1] > ll[:, 1]).all() and (_role(rec.track, "T1")[:, 0] < 0).all()
    assert struct.calcsize("<22f") == 88
