"""Sensor maps (cassi_fit.ema.sensor_map): the built-in names of each corpus, tongue order,
the TOML file, and the errors that name the sensors involved."""

from pathlib import Path

import pytest

from cassi_fit.ema.sensor_map import SensorMap, builtin_map, read_sensor_map, resolve
from cassi_fit.errors import DataFormatError

FIXTURES = Path(__file__).parent / "fixtures" / "ema"


def test_mocha_names():
    a = resolve(("ui", "li", "ul", "ll", "tt", "tb", "td", "v", "bn"), builtin_map("auto"))
    assert dict(a.roles) == {"UL": "ul", "LL": "ll", "T1": "tt", "T2": "tb", "T3": "td",
                             "MNI": "li"}
    assert a.extras == ("ui", "v", "bn")  # kept, not dropped
    assert a.upper_incisor == "ui" and a.references["nasion"] == ("bn",)
    assert "v" in a.midline and "ui" in a.midline


def test_tongue_sensors_ordered_front_to_back_whatever_the_file_order():
    a = resolve(("TR", "JAW", "TT", "UL", "TB"), builtin_map("auto"))  # Haskins-like names
    assert (a.roles["T1"], a.roles["T2"], a.roles["T3"]) == ("TT", "TB", "TR")
    assert "T4" not in a.roles and a.roles["MNI"] == "JAW"
    four = resolve(("T4", "T2", "t1", "T3"), builtin_map("auto"))
    assert [four.roles[r] for r in ("T1", "T2", "T3", "T4")] == ["t1", "T2", "T3", "T4"]
    mngu0 = resolve(("T1", "T2", "T3", "jaw", "upper_lip", "lower_lip", "ref"),
                    builtin_map("mngu0"))
    assert mngu0.roles["UL"] == "upper_lip" and mngu0.references["other"] == ("ref",)


def test_sparc_and_lab_names_with_spelling_variants():
    a = resolve(("Upper Lip", "lower-lip", "T.T", "LI", "NAS", "LMA", "RMA", "LC"),
                builtin_map("auto"))
    assert a.roles["UL"] == "Upper Lip" and a.roles["LL"] == "lower-lip"
    assert a.roles["T1"] == "T.T" and a.roles["MNI"] == "LI"
    assert a.reference_names == ("NAS", "LMA", "RMA") and a.extras[-1] == "LC"
    assert "LC" not in a.midline  # a lip corner is not on the midline


def test_toml_map_for_numbered_channels():
    smap = read_sensor_map(FIXTURES / "lab_sensors.toml")
    a = resolve(tuple(f"Ch{i}" for i in range(1, 11)), smap)
    assert a.names[:3] == ("NOSE", "LEFT_EAR", "RIGHT_EAR") and a.names[9] == "Ch10"
    assert a.roles["T2"] == "MID" and a.roles["MNI"] == "JAWS"
    assert a.references == {"nasion": ("NOSE",), "left": ("LEFT_EAR",), "right": ("RIGHT_EAR",)}
    assert a.extras == ("NOSE", "LEFT_EAR", "RIGHT_EAR", "Ch10")


@pytest.mark.parametrize("text, message", [
    ("[role]\nUL = 'A'\n", "unknown key 'role'"),
    ("[roles]\nUPPERLIP = 'A'\n", "unknown role 'UPPERLIP'"),
    ("[roles]\nUL = 'A'\nLL = 'a'\n", "given two roles"),
    ("[file]\nanterior = 'forward'\nup = '+y'\n", "expected an axis"),
    ("[file]\nanterior = '-x'\n", "needs both anterior and up"),
    ("[channels]\nfirst = 'A'\n", "channel number"),
    ("[bite_plane]\nmiddle = 'X'\n", "unknown key 'middle'"),
    ("[roles\nUL = 'A'\n", "not a TOML sensor map"),
    ("[file]\nanterior = 5\nup = '+y'\n", "anterior must be text"),
    ("[references]\nsensors = 3\n", "must be a name or a list"),
])
def test_toml_refusals_name_the_file(tmp_path, text, message):
    path = tmp_path / "map.toml"
    path.write_text(text)
    with pytest.raises(DataFormatError, match=message) as err:
        read_sensor_map(path)
    assert "map.toml" in str(err.value)


def test_resolution_errors_name_the_sensors():
    with pytest.raises(DataFormatError, match=r"role UL: sensor 'ULIP' is not in the file "
                       r"\(its sensors: A, B\)"):
        resolve(("A", "B"), SensorMap(roles={"UL": "ULIP"}))
    with pytest.raises(DataFormatError, match="'UL' and 'upper_lip' both look like UL"):
        resolve(("UL", "upper_lip", "LL"), builtin_map("auto"))
    with pytest.raises(DataFormatError, match="no sensor maps to a CASSI role.*Ch1, Ch2"):
        resolve(("Ch1", "Ch2"), builtin_map("auto"))
    with pytest.raises(DataFormatError, match="only 2 channels"):
        resolve(("Ch1", "Ch2"), SensorMap(channels={3: "UL"}))
    with pytest.raises(DataFormatError, match="'ul' is not in the file"):
        resolve(("UPPER", "LL"), builtin_map("mocha"))
    with pytest.raises(DataFormatError, match="unknown sensor map 'moca'"):
        builtin_map("moca")


def test_bite_sensors_only_required_in_a_bite_recording():
    smap = SensorMap(bite={"front": "PLATE1", "back": "PLATE2"})
    assert resolve(("UL", "LL"), smap).bite == {}
    with pytest.raises(DataFormatError, match="bite_plane back: sensor 'PLATE2'"):
        resolve(("PLATE1", "REF"), smap, bite_plane=True)
    a = resolve(("OS", "MS", "OL", "OR", "REF"), builtin_map("auto"), bite_plane=True)
    assert a.bite == {"front": "OS", "back": "MS", "left": "OL", "right": "OR"}
