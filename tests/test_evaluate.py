"""The objective evaluation: counting rule, thresholds, measured geometry, writers, CLI."""

import dataclasses
import logging
import shutil
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import zoo

from cassi_fit import cli, rigid
from cassi_fit import evaluate as ev
from cassi_fit.deform import default_params, deform
from cassi_fit.errors import (
    CassiError,
    DegenerateGeometryError,
    InvalidChoiceError,
    OutputExistsError,
)
from cassi_fit.face_model import load_model
from cassi_fit.status import Status

EPS = 1e-3

# A measure dict in which nothing is wrong (each value well inside its threshold).
CLEAN = {
    "lower_slope_deg": 0.0,
    "front_overlap_mm": 0.5,
    "back_overlap_mm": -0.5,
    "teeth_gap_mm": 0.5,
    "teeth_in_upper_lip_mm": 0.0,
    "teeth_in_lower_lip_mm": 0.0,
    "lip_gap_min_mm": 0.3,
    "lip_gap_median_mm": 3.0,
    "upper_lip_above_teeth_mm": -8.0,
    "lower_lip_below_teeth_mm": -8.0,
    "lower_lip_protrusion_mm": -1.0,
    "tongue_upper_front_mm": 0.0,
    "tongue_lower_front_mm": 0.0,
    "tongue_behind_incisors_mm": 7.0,
    "tongue_palate_mm": 0.0,
    "tongue_back_v_deg": -10.0,
    "palate_below_incisor_mm": -1.0,
    "tongue_upper_front_before_mm": 0.0,
    "tongue_lower_front_before_mm": 0.0,
    "tongue_palate_before_mm": 0.0,
    "teeth_in_lips_before_mm": 0.0,
    "airway_min_mm": 5.0,
    "frames_without_airway": 0,
    "tongue_volume_min_ml": 66.0,
    "tongue_volume_max_ml": 66.0,
    "tongue_pharynx_before_mm": 0.0,
}


def with_(**changes):
    assert set(changes) <= set(CLEAN)
    return {**CLEAN, **changes}


# ----------------------------------------------------------------------------- counting
@pytest.mark.parametrize(
    "n, word", [(0, "EXCELLENT"), (1, "VERY GOOD"), (2, "GOOD"), (3, "FAIR"), (5, "FAIR")]
)
def test_counting_rule(n, word):
    assert ev.rating(n) == word
    assert ev.RATINGS == ("EXCELLENT", "VERY GOOD", "GOOD", "FAIR")


@pytest.mark.parametrize("bad", [-1, 1.5, "2", True])
def test_rating_refuses_what_is_not_a_count(bad):
    with pytest.raises(CassiError):
        ev.rating(bad)


def test_clean_measures_have_no_problem():
    found = ev.problems(CLEAN)
    assert found == {"teeth": [], "lips": [], "tongue": [], "not_counted": []}
    assert set(CLEAN) == set(ev.MEASURES)


# (measure, threshold, direction: +1 = a problem above it, -1 = below it, component, name)
THRESHOLDS = [
    ("lower_slope_deg", ev.SLOPE_UP_DEG, +1, "teeth", "lower teeth slope up"),
    ("lower_slope_deg", -ev.SLOPE_DOWN_DEG, -1, "teeth", "lower teeth slope down"),
    ("front_overlap_mm", ev.FRONT_OVERLAP_MM, +1, "teeth", "front teeth overlap"),
    ("back_overlap_mm", ev.BACK_OVERLAP_MM, +1, "teeth", "back teeth overlap"),
    ("teeth_in_upper_lip_mm", ev.TEETH_IN_LIPS_MM, +1, "teeth", "teeth run into the lips"),
    ("teeth_in_lower_lip_mm", ev.TEETH_IN_LIPS_MM, +1, "teeth", "teeth run into the lips"),
    ("teeth_gap_mm", ev.TEETH_APART_MM, +1, "teeth", "teeth too far apart"),
    ("lip_gap_min_mm", ev.LIP_APART_MM, +1, "lips", "lips never touch"),
    ("lip_gap_median_mm", -ev.LIP_TIGHT_MM, -1, "lips", "lips too tightly together"),
    ("upper_lip_above_teeth_mm", ev.LIP_BEYOND_TEETH_MM, +1, "lips",
     "upper lip above the upper teeth"),
    ("lower_lip_below_teeth_mm", ev.LIP_BEYOND_TEETH_MM, +1, "lips",
     "lower lip below the lower teeth"),
    ("lower_lip_protrusion_mm", ev.LIP_PROTRUSION_MM, +1, "lips", "lower lip protrudes"),
    ("tongue_upper_front_mm", ev.TONGUE_POKE_MM, +1, "tongue",
     "tongue through upper front teeth"),
    ("tongue_lower_front_mm", ev.TONGUE_POKE_MM, +1, "tongue",
     "tongue through lower front teeth"),
    ("tongue_behind_incisors_mm", ev.TONGUE_HIDDEN_MM, +1, "tongue", "tongue barely visible"),
    ("tongue_palate_mm", ev.TONGUE_PALATE_MM, +1, "not_counted", "tongue through the palate"),
    ("palate_below_incisor_mm", ev.PALATE_BELOW_MM, +1, "not_counted",
     "palate below the upper incisor tip"),
    ("tongue_back_v_deg", ev.TONGUE_V_DEG, +1, "not_counted", "tongue's back in a V"),
]  # fmt: skip


@pytest.mark.parametrize("name, limit, direction, component, problem", THRESHOLDS)
def test_each_threshold(name, limit, direction, component, problem):
    inside = ev.problems(with_(**{name: limit - direction * EPS}))
    beyond = ev.problems(with_(**{name: limit + direction * EPS}))
    assert problem not in inside[component]
    assert beyond[component] == [problem]
    others = [c for c in ("teeth", "lips", "tongue", "not_counted") if c != component]
    assert all(beyond[c] == [] for c in others)
    if component != "not_counted":  # reported, never rated
        assert ev.rate(with_(**{name: limit + direction * EPS}))[1][component] == "VERY GOOD"


def test_not_counted_problems_leave_the_ratings_excellent():
    found, ratings = ev.rate(with_(tongue_palate_mm=9.0, palate_below_incisor_mm=2.0))
    assert len(found["not_counted"]) == 2
    assert ratings == {"teeth": "EXCELLENT", "lips": "EXCELLENT", "tongue": "EXCELLENT"}


@pytest.mark.parametrize(
    "slope, count",
    [
        (ev.SLOPE_UP_DEG - EPS, 0),
        (ev.SLOPE_UP_DEG + EPS, 1),
        (ev.SLOPE_STEEP_DEG - EPS, 1),
        (ev.SLOPE_STEEP_DEG + EPS, 2),
        (ev.SLOPE_VERY_STEEP_DEG - EPS, 2),
        (ev.SLOPE_VERY_STEEP_DEG + EPS, 3),
        (40.0, 3),
    ],
)
def test_steeper_slopes_count_up_to_three(slope, count):
    teeth = ev.problems(with_(lower_slope_deg=slope))["teeth"]
    assert len(teeth) == count
    assert ev.rating(len(teeth)) == ev.RATINGS[count]


@pytest.mark.parametrize(
    "gap, count",
    [
        (ev.LIP_APART_MM - EPS, 0),
        (ev.LIP_APART_MM + EPS, 1),
        (ev.LIP_APART_LARGE_MM - EPS, 1),
        (ev.LIP_APART_LARGE_MM + EPS, 2),
    ],
)
def test_a_large_lip_gap_counts_two(gap, count):
    assert len(ev.problems(with_(lip_gap_min_mm=gap))["lips"]) == count


@pytest.mark.parametrize(
    "upper, lower, count",
    [
        (0.0, 0.0, 0),
        (ev.TONGUE_POKE_MM + EPS, 0.0, 1),
        (0.0, ev.TONGUE_POKE_MM + EPS, 1),
        (8.0, 0.0, 1),  # very deep through one arch is still one
        (ev.TONGUE_POKE_MM + EPS, ev.TONGUE_POKE_MM + EPS, 2),
        (8.0, ev.TONGUE_POKE_DEEP_MM - EPS, 2),  # very noticeable needs both
        (ev.TONGUE_POKE_DEEP_MM + EPS, ev.TONGUE_POKE_DEEP_MM + EPS, 3),
    ],
)
def test_tongue_through_one_both_or_very_noticeably_both(upper, lower, count):
    found = ev.problems(with_(tongue_upper_front_mm=upper, tongue_lower_front_mm=lower))
    assert len(found["tongue"]) == count


def test_problems_add_up_across_kinds():
    teeth = with_(
        lower_slope_deg=ev.SLOPE_VERY_STEEP_DEG + 1,  # three
        front_overlap_mm=ev.FRONT_OVERLAP_MM + 1,
        back_overlap_mm=ev.BACK_OVERLAP_MM + 1,  # one with the front overlap
        teeth_in_lower_lip_mm=3.0,
    )
    found, ratings = ev.rate(teeth)
    assert len(found["teeth"]) == 5
    assert "front and back teeth overlap" in found["teeth"]
    assert ratings["teeth"] == "FAIR"
    lips = with_(lip_gap_median_mm=-3.0, lower_lip_protrusion_mm=2.0)
    found, ratings = ev.rate(lips)
    assert found["lips"] == ["lips too tightly together", "lower lip protrudes"]
    assert ratings["lips"] == "GOOD"
    tongue = with_(tongue_upper_front_mm=2.0, tongue_behind_incisors_mm=20.0)
    assert ev.rate(tongue)[1]["tongue"] == "GOOD"


def test_missing_or_nan_measure_is_not_rated():
    broken = dict(CLEAN)
    del broken["teeth_gap_mm"]
    with pytest.raises(CassiError, match="teeth_gap_mm"):
        ev.problems(broken)
    with pytest.raises(DegenerateGeometryError, match="nan"):
        ev.problems(with_(lip_gap_min_mm=float("nan")))


def test_describe_collapses_repeats():
    assert ev.describe(["a", "a", "b", "a"]) == "a x3; b"
    assert ev.describe([]) == ""


# ----------------------------------------------------------------------------- statistics
def test_one_bad_frame_does_not_decide_but_a_held_one_does():
    x = np.zeros(100)
    x[40] = 9.0  # one frame
    assert ev.sustained_max(x, 7) == 0.0
    x[60:67] = 5.0  # held for 7 frames
    assert ev.sustained_max(x, 7) == 5.0
    assert ev.sustained_max(x, 8) == 0.0
    assert ev.sustained_min(-x, 7) == -5.0
    assert ev.sustained_max(np.array([1.0, 3.0]), 7) == 1.0  # shorter than the window


def test_sustain_window_from_frame_times():
    assert ev.sustain_frames(np.arange(50) * 6866e-6) == 7
    assert ev.sustain_frames(np.arange(50) * 10 * 6866e-6) == 1
    assert ev.sustain_frames(np.zeros(1)) == 1
    with pytest.raises(DegenerateGeometryError):
        ev.sustain_frames(np.zeros(5))


def test_combine_takes_the_sensible_direction():
    a = with_(lip_gap_min_mm=4.0, tongue_upper_front_mm=0.5, lower_slope_deg=2.0)
    b = with_(lip_gap_min_mm=-1.0, tongue_upper_front_mm=3.0, lower_slope_deg=4.0)
    both = ev.combine([a, b])
    assert both["lip_gap_min_mm"] == -1.0  # one task closing the lips clears the subject
    assert both["tongue_upper_front_mm"] == 3.0  # one task poking through counts
    assert both["lower_slope_deg"] == 4.0  # the most closed jaw seen
    assert ev.problems(ev.combine([a]))["lips"] == ["lips never touch"]
    assert ev.problems(both)["lips"] == []
    with pytest.raises(CassiError):
        ev.combine([])


# ----------------------------------------------------------------------------- geometry
@pytest.fixture(scope="module")
def model():
    return load_model()


_POSE = {}


def posed(model, frames=8, **changes):
    """An animation-like object: the model posed by ``changes`` for ``frames`` frames."""
    params = dataclasses.replace(
        default_params(model), **{k: jnp.asarray(v, float) for k, v in changes.items()}
    )
    if id(model) not in _POSE:  # one compilation for every pose of the module's model
        _POSE[id(model)] = jax.jit(lambda p: deform(model, p))
    vertices = _POSE[id(model)](params)
    return SimpleNamespace(
        vertices=jnp.broadcast_to(vertices, (frames, *vertices.shape)),
        times=np.arange(frames) * 6866e-6,
    )


def opened(model, theta):
    """Jaw params opening by ``theta`` rad about the model's condyle."""
    pivot = (model.measures["jaw_pivot_x"], model.measures["jaw_pivot_y"])
    theta, t = rigid.from_pivot(jnp.asarray(theta), jnp.asarray(pivot))
    return {"jaw_theta": theta, "jaw_translation": t}


def test_rest_model_measures(model):
    state = SimpleNamespace(model=model)
    m = ev.measure(state, posed(model))
    assert set(m) == set(ev.MEASURES)
    # rows A and B (the lips' edges) at 1.9 and 0.3 mm: parted at rest, the upper incisor shows
    assert m["lip_gap_min_mm"] == pytest.approx(1.6, abs=0.05)
    assert m["front_overlap_mm"] == pytest.approx(-0.5, abs=0.05)  # lower tip 0.5 below
    assert abs(m["lower_slope_deg"]) < 0.5
    assert m["tongue_upper_front_mm"] < 0.05 and m["tongue_lower_front_mm"] < 0.05
    assert m["palate_below_incisor_mm"] < 0.0
    assert m["tongue_volume_min_ml"] == pytest.approx(m["tongue_volume_max_ml"])
    assert 55.0 < m["tongue_volume_min_ml"] < 113.0  # the adult range (docs/TONGUE.md)
    assert ev.rate(m)[1] == {"teeth": "EXCELLENT", "lips": "EXCELLENT", "tongue": "EXCELLENT"}


def test_opening_the_jaw_opens_the_gaps(model):
    state = SimpleNamespace(model=model)
    rest = ev.measure(state, posed(model))
    wide = ev.measure(state, posed(model, **opened(model, 0.25)))
    assert wide["lip_gap_min_mm"] > rest["lip_gap_min_mm"] + 10.0
    assert wide["teeth_gap_mm"] > rest["teeth_gap_mm"] + 10.0
    assert wide["lower_slope_deg"] == pytest.approx(-np.degrees(0.25), abs=0.5)
    found = ev.problems(wide)
    assert found["teeth"] == ["lower teeth slope down", "teeth too far apart"]
    assert found["lips"] == ["lips far apart"] * 2
    closed_past_rest = ev.measure(state, posed(model, **opened(model, -0.06)))
    assert closed_past_rest["front_overlap_mm"] > ev.FRONT_OVERLAP_MM
    assert "lower teeth slope up" in ev.problems(closed_past_rest)["teeth"]


def test_tongue_pushed_forward_pokes_through_the_front_teeth(model):
    state = SimpleNamespace(model=model)
    forward = np.tile([12.0, 2.0], (4, 1))
    m = ev.measure(state, posed(model, tongue=forward))
    rest = ev.measure(state, posed(model))
    assert m["tongue_upper_front_mm"] + m["tongue_lower_front_mm"] > 2 * ev.TONGUE_POKE_MM
    assert m["tongue_behind_incisors_mm"] < rest["tongue_behind_incisors_mm"] - 10.0
    assert ev.problems(m)["tongue"]
    back = ev.measure(state, posed(model, tongue=np.tile([-15.0, 0.0], (4, 1))))
    assert back["tongue_behind_incisors_mm"] > ev.TONGUE_HIDDEN_MM
    assert ev.problems(back)["tongue"] == ["tongue barely visible"]


def test_non_finite_geometry_raises(model):
    anim = posed(model)
    anim.vertices = anim.vertices.at[3, model.landmarks["lower_incisor_tip"], 1].set(jnp.nan)
    with pytest.raises(DegenerateGeometryError, match="frame 3"):
        ev.measure(SimpleNamespace(model=model), anim)


def test_penetration_from_the_animation_is_used(model):
    anim = posed(model)
    from cassi_fit.collide import REPORT_KEYS

    zeros = {k: np.zeros(8) for k in REPORT_KEYS}
    deep = {**zeros, "tongue_upper_front": np.full(8, 3.0)}
    anim.penetration, anim.penetration_after = deep, zeros  # projected away
    m = ev.measure(SimpleNamespace(model=model), anim)
    assert m["tongue_upper_front_mm"] == 0.0
    assert m["tongue_upper_front_before_mm"] == 3.0


def test_a_second_animation_of_the_same_shape_compiles_nothing(model, caplog):
    state = SimpleNamespace(model=model)
    ev.measure(state, posed(model))  # compiles the per-frame kernel and the report
    other = posed(model, **opened(model, 0.1))  # new content, same shapes
    with jax.log_compiles(), caplog.at_level(logging.WARNING):
        m = ev.measure(state, other)
    compiled = [r.getMessage() for r in caplog.records if r.getMessage().startswith("Compiling")]
    assert compiled == []
    assert m["teeth_gap_mm"] > ev.measure(state, posed(model))["teeth_gap_mm"]  # measured anew


# ----------------------------------------------------------------------------- writers
SETTINGS = {"stride": 1, "jaw": "closed-form", "collisions": "off"}


def hand_result(with_unrated=False):
    """S01 clean, S02 with its lips far apart and one failed task (and, ``with_unrated``,
    S03 whose only task failed)."""
    bad_lips = with_(lip_gap_min_mm=ev.LIP_APART_LARGE_MM + 1, tongue_palate_mm=3.0)
    ok = dict(frames=10, calibration="cassi", **SETTINGS)
    failed = "S02/tp106: jaw pellet(s) MNI never tracked"
    recs = [
        ev.RecordingRow.evaluated("S01", "tp040", CLEAN, **ok),
        ev.RecordingRow.evaluated("S02", "tp040", bad_lips, **ok),
        ev.RecordingRow.not_evaluated("S02", "tp106", failed, calibration="cassi", **SETTINGS),
    ]
    names = ("S01", "S02")
    if with_unrated:
        recs.append(ev.RecordingRow.not_evaluated("S03", "tp040", "S03/tp040: bad",
                                                  calibration="cassi", **SETTINGS))
        names += ("S03",)
    subjects = [ev.SubjectRow.of_recordings(s, [r for r in recs if r.subject == s], **SETTINGS)
                for s in names]
    return ev.EvaluationResult(recs, subjects, {**SETTINGS, "calibration": "cassi"})


def test_rows_are_typed_records_with_a_status():
    result = hand_result(with_unrated=True)
    s01, s02_ok, s02_bad, s03 = result.recordings
    assert s01.status is Status.OK and s01.rated and s01.error == ""
    assert s01.ratings == {"teeth": "EXCELLENT", "lips": "EXCELLENT", "tongue": "EXCELLENT"}
    assert s02_bad.status is Status.FAILED and not s02_bad.rated
    assert s02_bad.error == "S02/tp106: jaw pellet(s) MNI never tracked"
    assert (s02_bad.frames, s02_bad.measures, s02_bad.ratings) == (0, {}, {})
    assert result.failed == [s02_bad, s03]
    s1, s2, s3 = result.subjects
    assert (s2.tasks, s2.recordings, s2.failed, s2.calibration) == ("tp040", 1, 1, "cassi")
    assert s2.measures == s02_ok.measures and s2.ratings["lips"] == "GOOD"
    assert s3.status is Status.FAILED and s3.error == ev.NO_RECORDING
    assert (s3.tasks, s3.recordings, s3.failed, s3.calibration, s3.ratings) == ("", 0, 1, "",
                                                                                {})
    with pytest.raises(dataclasses.FrozenInstanceError):
        s01.status = Status.FAILED
    with pytest.raises(CassiError, match="one-line error"):
        ev.RecordingRow("S01", "tp040", Status.FAILED, 0, 1, "closed-form", "cassi", "off")
    with pytest.raises(CassiError, match="carries an error"):
        ev.RecordingRow("S01", "tp040", Status.OK, 5, 1, "closed-form", "cassi", "off",
                        error="boom")
    with pytest.raises(CassiError, match="not-converged"):
        ev.RecordingRow("S01", "tp040", Status.NOT_CONVERGED, 5, 1, "closed-form", "cassi",
                        "off")


def test_markdown_table_layout():
    result = hand_result()
    assert result.totals() == {"teeth": (2, 0, 0, 0), "lips": (1, 0, 1, 0),
                               "tongue": (2, 0, 0, 0)}
    text = ev.markdown_table(result)
    lines = text.splitlines()
    header = lines.index("| Subject | Tasks | Teeth | Lips | Tongue |")
    assert lines[header + 1] == "|---|---|---|---|---|"
    assert lines[header + 2] == "| S01 | tp040 | EXCELLENT | EXCELLENT | EXCELLENT |"
    assert lines[header + 3] == "| S02 | tp040 | EXCELLENT | GOOD (lips far apart x2) | EXCELLENT |"
    assert lines[header + 4] == ("| **Total** (EXCELLENT/VERY GOOD/GOOD/FAIR) | | 2/0/0/0 | "
                                 "1/0/1/0 | 2/0/0/0 |")
    assert "S02: tongue through the palate" in text
    assert "S02 tp106 (S02/tp106: jaw pellet(s) MNI never tracked)" in text
    unrated = ev.markdown_table(hand_result(with_unrated=True)).splitlines()
    assert "| S03 |  | not rated | not rated | not rated |" in unrated


def test_write_table_csv_and_refusal(tmp_path):
    import csv

    result = hand_result()
    paths = ev.write_table(result, tmp_path)
    assert [p.name for p in paths] == list(ev.OUTPUT_NAMES)
    with open(tmp_path / "evaluation_recordings.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["task"] for r in rows] == ["tp040", "tp040", "tp106"]
    assert rows[1]["lips_rating"] == "GOOD" and rows[1]["lips_problems_n"] == "2"
    assert float(rows[1]["lip_gap_min_mm"]) == pytest.approx(ev.LIP_APART_LARGE_MM + 1)
    assert (rows[2]["status"], rows[2]["error"]) == (
        "failed", "S02/tp106: jaw pellet(s) MNI never tracked")
    assert rows[2]["frames"] == "0" and rows[2]["lips_rating"] == ""
    with open(tmp_path / "evaluation_subjects.csv", newline="") as fh:
        subjects = list(csv.DictReader(fh))
    assert [(s["subject"], s["recordings"], s["failed"]) for s in subjects] == [
        ("S01", "1", "0"), ("S02", "1", "1")]
    before = (tmp_path / "evaluation.md").read_text()
    assert "| S02 | tp040 |" in before
    with pytest.raises(OutputExistsError):
        ev.write_table(result, tmp_path)
    assert (tmp_path / "evaluation.md").read_text() == before
    ev.write_table(result, tmp_path, overwrite=True)
    ev.write_table(hand_result(with_unrated=True), tmp_path, overwrite=True)
    with open(tmp_path / "evaluation_subjects.csv", newline="") as fh:
        s03 = list(csv.DictReader(fh))[2]
    assert (s03["subject"], s03["status"], s03["error"], s03["tasks"], s03["calibration"]) == (
        "S03", "failed", "no recording evaluated", "", "")
    assert s03["teeth_rating"] == "" and s03["lip_gap_min_mm"] == ""


def test_plot_and_compare(tmp_path):
    result = hand_result()
    png = ev.plot_summary(result, tmp_path / "summary.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(OutputExistsError):
        ev.plot_summary(result, png)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.png"]  # no temporary left
    text = ev.compare(result, result, labels=("CASSI-like", "calibrated + collisions"))
    assert "| CASSI (paper, 15 subjects; FAIR as 3) | 1/6/6/2 | 2/7/4/2 | 2/4/6/3 |" in text
    assert "| CASSI-like (2 subjects) | 2/0/0/0 | 1/0/1/0 | 2/0/0/0 | 0.0/1.0/0.0 |" in text


# ----------------------------------------------------------------------------- end to end
@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """One synthetic subject with a sentence, plus a recording whose jaw is never tracked."""
    from cassi_fit.txy import PelletTrack, read_txy, write_txy

    root = zoo.small_corpus(tmp_path_factory, n_subjects=1, tasks=("tp040",))
    copy = tmp_path_factory.mktemp("eval_corpus")
    shutil.copytree(root, copy, dirs_exist_ok=True)
    folder = copy / "S01"
    track = read_txy(folder / "TP040.TXY")
    valid = np.array(track.valid)
    valid[:, 6:8] = False  # MNI, MNM never tracked
    write_txy(folder / "TP999.TXY", PelletTrack(track.times, track.positions, valid))
    return copy


def _run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_evaluate_cassi_like(corpus, tmp_path, capsys):
    out = tmp_path / "eval"
    # every test animates at stride 20 (34 frames: the frame bucket of most animations in
    # the suite, whose compiled kernels it shares); in this process (--jobs 1), where what
    # it compiles stays for the next test (worker processes each trace and compile the
    # whole pipeline again; the runner's workers have their tests in test_corpus.py and
    # test_cli_corpus.py)
    code, text, err = _run(capsys, "evaluate", corpus, "--out", out, "--cassi", "--quiet",
                           "--stride", "20", "--jobs", "1")
    assert code == 1, err  # tp999 failed: the run goes on, then exits non-zero (issue 15)
    assert "1 of 2 failed:" in err
    assert "| Subject | Tasks | Teeth | Lips | Tongue |" in text
    assert "| S01 | tp040 |" in text
    assert "S01 tp999 (" in text and "never tracked" in text  # the broken file is reported, not rated
    assert "Calibration: cassi mode; collisions: off; jaw: closed-form; stride 20" in text
    names = sorted(p.name for p in out.iterdir() if p.name != ".cassi-corpus")  # markers
    assert names == sorted([*ev.OUTPUT_NAMES, "evaluation_summary.png"])
    code, _, err = _run(capsys, "evaluate", corpus, "--out", out, "--quiet")
    assert code == 2 and "exists" in err and len(err.strip().splitlines()) == 1
    code, _, err = _run(capsys, "evaluate", corpus, "--out", out, "--cassi", "--collisions",
                        "project", "--quiet")
    assert code == 2 and "--cassi" in err


def test_evaluate_dataset_rows(corpus):
    result = ev.evaluate_dataset(corpus, calibration="cassi", tasks=["tp040"], progress=False,
                                 stride=20)
    (row,) = result.recordings
    assert (row.subject, row.task, row.status, row.stride) == ("S01", "tp040", Status.OK, 20)
    assert row.calibration == "cassi" and row.frames > 0 and row.error == ""
    assert set(row.measures) == set(ev.MEASURES)
    assert all(np.isfinite(v) for v in row.measures.values())
    # the improved tongue keeps its volume over the recording (docs/TONGUE.md)
    low, high = row.measures["tongue_volume_min_ml"], row.measures["tongue_volume_max_ml"]
    assert 55.0 < low <= high < 1.03 * low
    (subject,) = result.subjects
    assert subject.tasks == "tp040"
    assert subject.ratings == row.ratings
    assert subject.measures == row.measures
    with pytest.raises(CassiError, match="tp404"):
        ev.evaluate_dataset(corpus, tasks=["tp404"], progress=False)


def test_cli_calibration_folder_is_loaded_per_subject(corpus, tmp_path, capsys, monkeypatch):
    from cassi_fit import calibration

    seen = []

    def fake_load(folder):  # read once before the run; the folder lacks S01's file
        seen.append(folder)
        return {}

    monkeypatch.setattr(calibration, "load_calibrations", fake_load)
    folder = tmp_path / "calibrations"
    folder.mkdir()
    out = tmp_path / "eval"
    code, text, err = _run(capsys, "evaluate", corpus, "--calibration", folder, "--out",
                           out, "--tasks", "tp040", "--stride", "20", "--quiet")
    assert code == 1 and seen == [folder]  # S01's recording: a failed row, not a default
    assert f"{folder}: no calibration of subject S01 (S01.calibration.json; it has no" in err
    with open(out / "evaluation_recordings.csv") as fh:
        assert "no calibration of subject S01" in fh.read()
    code, _, err = _run(capsys, "evaluate", corpus, "--calibration", tmp_path / "nowhere",
                        "--out", tmp_path / "other", "--quiet")
    assert code == 2 and "no such calibration file or folder" in err


def test_bad_choices_are_refused_before_animating(corpus):
    # unchecked, each of these would only fail every recording one by one (FAILED rows)
    with pytest.raises(InvalidChoiceError, match="collisions"):
        ev.evaluate_dataset(corpus, collisions="push", progress=False)
    with pytest.raises(InvalidChoiceError, match="jaw method"):
        ev.evaluate_dataset(corpus, jaw="hinge", progress=False)
    with pytest.raises(InvalidChoiceError, match="calibration"):
        ev.evaluate_dataset(corpus, calibration=3, progress=False)
    with pytest.raises(CassiError, match="stride"):
        ev.evaluate_dataset(corpus, stride=0, progress=False)
