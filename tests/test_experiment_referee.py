"""The real-referee experiment: held-out sensors scored against the recording.

The scoring on recordings whose answer is known (the truth scores zero, a wrong pivot its
hand-computed error, the trivial baselines theirs), the bootstrap on cases with a known
sampling spread, and a re-run of a slice of the experiment against the generated table.
"""

import sys
from pathlib import Path

import numpy as np
import pytest
from real_data import XRMB_JW11, missing, real_data  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import real_referee  # noqa: E402
import referee_parts  # noqa: E402
import referee_report  # noqa: E402
import referee_rows  # noqa: E402
import zoo  # noqa: E402

GENERATED = ROOT / "docs" / "generated" / "real_referee.csv"
GENERATED_COUPLINGS = ROOT / "docs" / "generated" / "real_referee_couplings.csv"
GENERATED_MD = GENERATED.with_suffix(".md")
# The real recording (read-only, never copied; tests/real_data.py says where it is looked for)
JW11 = real_data(XRMB_JW11)
KEY = ("dataset", "subject", "task", "part", "metric", "predictor", "versus")


def _track(mni, mnm, others=None):
    """A PelletTrack (n frames at the XRMB rate) with the jaw pellets given (n, 2) mm and
    the other pellets at ``others`` (8, 2) mm (fixed) or untracked."""
    from cassi_fit.txy import PelletTrack

    n = len(mni)
    positions = np.zeros((n, 8, 2))
    valid = np.zeros((n, 8, 2), bool)
    if others is not None:
        positions[:] = others
        valid[:] = True
    positions[:, 6], positions[:, 7] = mni, mnm
    valid[:, 6:8] = True
    return PelletTrack(np.arange(n) * 6866e-6, positions, valid)


def _rotation_about(q, theta, p):
    c, s = np.cos(theta), np.sin(theta)
    u = p - q
    return np.stack([c * u[0] + s * u[1], -s * u[0] + c * u[1]], -1) + q


@pytest.fixture(scope="module")
def pure_rotation():
    """The jaw turning about a known pivot by a known angle per frame (0 at frame 0)."""
    q = np.array([-95.0, 25.0])
    mni0, mnm0 = np.array([-2.0, -8.0]), np.array([-32.0, -14.0])
    theta = np.deg2rad(6.0) * np.sin(np.linspace(0.0, 6 * np.pi, 600)) ** 2
    return q, theta, mni0, mnm0, _track(_rotation_about(q, theta, mni0),
                                        _rotation_about(q, theta, mnm0))


def test_the_baselines_and_a_wrong_pivot_score_their_known_errors(pure_rotation):
    q, theta, mni0, mnm0, track = pure_rotation
    chord = 2.0 * np.abs(np.sin(theta / 2.0))  # |(R - I) v| = 2 |sin(theta/2)| |v|
    [part] = referee_parts.jaw_part(track, "MNI")
    frames = part.frames
    assert part.part == "jaw: MNM from MNI" and 0 not in frames and len(frames) == 599
    np.testing.assert_allclose(part.errors["static"], chord[frames] * np.linalg.norm(mnm0 - q),
                               atol=1e-9)
    np.testing.assert_allclose(part.errors["translate"],
                               chord[frames] * np.linalg.norm(mnm0 - mni0), atol=1e-9)
    # both references see the true rigid motion about a fixed pivot: the truth scores zero
    assert part.errors["two-pellet fixed pivot"].max() < 1e-6
    assert part.errors["two-pellet pivot, seen angle"].max() < 1e-6
    # a pivot 12 mm off, with the true angles: every point misses by 2 |sin(theta/2)| 12 mm
    wrong = q + np.array([12.0 * 0.6, -12.0 * 0.8])
    predicted = referee_parts.rotate_about(wrong, theta, mnm0)
    errors = referee_parts.point_errors(predicted, track.positions[:, 7])
    np.testing.assert_allclose(errors, 12.0 * chord, atol=1e-9)
    assert errors.max() > 1.0
    # the seen sensor's angle about the true pivot is the true angle
    np.testing.assert_allclose(referee_parts.angle_about(q, mni0, track.positions[:, 6]), theta,
                               atol=1e-12)


def test_the_truth_scores_zero_on_a_synthetic_recording():
    """Noise-free synthetic jaw about a fixed condyle: the two-pellet references, whose
    model is the truth's, predict either hidden sensor to the file's 1 um rounding, while
    the baselines miss by millimetres."""
    from cassi_fit import synth

    anatomy = synth.make_subject("X01", np.random.default_rng(300), jaw_kinematics="fixed-condyle")
    track, truth = synth.synth_recording(anatomy, "tp106", seed=1, noise_mm=0.0, duration_s=4.0,
                                         dropouts=False, mistracks=False)  # fmt: skip
    fit = referee_parts.two_pellet_fit(track)
    np.testing.assert_allclose(fit[2], truth.condyle[0], atol=0.05)  # the pivot is the condyle
    for seen in ("MNI", "MNM"):
        [part] = referee_parts.jaw_part(track, seen, fit)
        assert len(part.frames) > 500
        assert part.errors["two-pellet fixed pivot"].max() < 0.01
        assert part.errors["two-pellet pivot, seen angle"].max() < 0.01
        assert np.median(part.errors["static"]) > 1.0
        assert np.median(part.errors["translate"]) > 0.5


def test_distance_to_a_polyline_and_the_arc_to_its_foot():
    line = np.array([[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]] * 4)
    points = np.array([[4.0, 3.0], [12.0, 5.0], [-3.0, -4.0], [13.0, 14.0]])
    dist, arc = referee_parts.polyline_distance(points, line)
    np.testing.assert_allclose(dist, [3.0, 2.0, 5.0, 5.0])
    np.testing.assert_allclose(arc, [4.0, 15.0, 0.0, 20.0])
    np.testing.assert_allclose(referee_parts.arc_lengths(line)[0], [0.0, 10.0, 20.0])


def _result(values, other, step_s=6866e-6, part="p"):
    return referee_parts.PartResult(part, "position", {"a": values, "b": other},
                                   {"a": "method", "b": "baseline"}, step_s)


def test_the_bootstrap_interval_of_a_median_of_independent_frames():
    """Independent normal frames, blocks of one frame: the 95 % interval of the median is
    +-1.96 sqrt(pi/2) sigma / sqrt(n) (the median's asymptotic standard error; the
    bootstrap of a median converges slowly, as n^-1/4, hence the tolerance)."""
    rng = np.random.default_rng(5)
    n, sigma = 4000, 2.0
    values = 10.0 + sigma * rng.standard_normal(n)
    result = _result(values, values + 0.5, step_s=referee_parts.BLOCK_S)  # block = 1 frame
    assert result.block == 1
    row = referee_rows.recording_rows("d", "S", "t", result)[0]
    half = 1.96 * np.sqrt(np.pi / 2) * sigma / np.sqrt(n)
    assert row["median_hi_mm"] - row["median_lo_mm"] == pytest.approx(2 * half, rel=0.25)
    assert row["median_lo_mm"] < np.median(values) < row["median_hi_mm"]


def test_the_block_bootstrap_follows_correlated_frames():
    """AR(1) frames (correlation 0.95 per frame): the median's sampling spread, measured on
    800 independent series, is matched by the moving-block interval of one series, while
    a bootstrap of single frames is several times too narrow."""
    rng = np.random.default_rng(11)
    n, rho = 1500, 0.95
    shocks = rng.standard_normal((801, n)) * np.sqrt(1 - rho**2)
    series = np.empty_like(shocks)
    series[:, 0] = rng.standard_normal(801)
    for k in range(1, n):
        series[:, k] = rho * series[:, k - 1] + shocks[:, k]
    true_width = np.subtract(*np.percentile(np.median(series[1:], axis=1), [97.5, 2.5]))
    widths = {}
    for step in (referee_parts.BLOCK_S / 100, referee_parts.BLOCK_S):  # blocks of 100, 1
        result = _result(series[0], series[0], step_s=step)
        row = referee_rows.recording_rows("d", "S", "t", result)[0]
        widths[result.block] = row["median_hi_mm"] - row["median_lo_mm"]
    assert widths[100] == pytest.approx(true_width, rel=0.3)
    assert widths[1] < 0.5 * true_width


def test_paired_rows_say_tie_unless_the_interval_excludes_zero():
    rng = np.random.default_rng(2)
    values = np.abs(rng.standard_normal(700))
    rows = referee_rows.recording_rows("d", "S", "t", _result(values, values + 0.3))
    [paired] = [r for r in rows if r["versus"] == "b"]
    assert paired["median_mm"] == pytest.approx(-0.3)
    assert paired["median_lo_mm"] == pytest.approx(-0.3) and paired["median_verdict"] == "better"
    rows = referee_rows.recording_rows("d", "S", "t", _result(values + 0.3, values))
    assert [r["p95_verdict"] for r in rows if r["versus"]] == ["worse"]
    noisy = values + 0.05 * rng.standard_normal(700)  # no real difference
    rows = referee_rows.recording_rows("d", "S", "t", _result(values, noisy))
    assert [r["median_verdict"] for r in rows if r["versus"]] == ["tie"]


def test_pooled_rows_resample_subjects():
    """Two subjects whose errors differ by 1 mm: the pooled median's interval spans the
    subject-to-subject difference (the subjects are resampled), a single subject's does not."""
    rng = np.random.default_rng(3)
    results = [(s, t, _result(offset + 0.1 * rng.standard_normal(400), np.zeros(400) + offset))
               for s, offset in (("S1", 1.0), ("S2", 2.0)) for t in ("t1", "t2")]
    [row] = [r for r in referee_rows.pooled_rows("d", results) if r["predictor"] == "a"
             and not r["versus"]]
    assert (row["recordings"], row["subjects"], row["frames"]) == (4, 2, 1600)
    assert row["median_lo_mm"] < 1.2 and row["median_hi_mm"] > 1.8
    [one] = [r for r in referee_rows.pooled_rows("d", results[:2]) if r["predictor"] == "a"
             and not r["versus"]]
    assert one["median_hi_mm"] - one["median_lo_mm"] < 0.1


# ------------------------------------------------------------- the generated table
@pytest.fixture(scope="module")
def generated():
    if not GENERATED.exists():
        pytest.fail(f"{GENERATED} missing: run `make experiments`")
    return referee_rows.parse_rows(GENERATED.read_text())


@pytest.fixture(scope="module")
def couplings():
    return referee_rows.parse_rows(GENERATED_COUPLINGS.read_text())


def test_couplings_are_learned_on_other_speakers_only():
    couplings = referee_parts.Couplings({("a", "S1"): [], ("a", "S2"): [], ("a", "S3"): [],
                                        ("real", "JW11"): []})
    assert couplings.training("a", "S2") == [("a", "S1"), ("a", "S3")]
    assert couplings.training("real", "JW11") == [("a", "S1"), ("a", "S2"), ("a", "S3")]


def _compare(fresh, generated):
    """Every freshly computed row is in the table with the same numbers, and the table
    holds no other row for those recordings and parts."""
    index = {tuple(r[k] for k in KEY): r for r in generated}
    assert fresh
    for row in fresh:
        key = tuple(row[k] for k in KEY)
        assert key in index, f"not in {GENERATED.name} (stale?): {key}"
        for column, value in row.items():
            if isinstance(value, float):
                assert index[key][column] == pytest.approx(value, abs=2e-6), (key, column)
            else:
                assert index[key][column] == value, (key, column)
    scope = {(r["dataset"], r["subject"], r["task"], r["part"], r["metric"]) for r in fresh}
    extra = [r for r in generated if (r["dataset"], r["subject"], r["task"], r["part"],
                                      r["metric"]) in scope]
    assert len(extra) == len(fresh)


def _slice(dataset, subject, task, recording, couplings):
    """The cheap parts of the experiment on one recording: the jaw (its coupling read from
    the couplings table) and the lips."""
    learned = {c["sensor"]: referee_parts.coupling_from_row(c) for c in couplings
               if (c["dataset"], c["subject"]) == (dataset, subject)}
    single = referee_parts.single_sensor_predictor(learned.__getitem__)
    fit = referee_parts.two_pellet_fit(recording.track)
    parts = [p for seen in referee_parts.JAW
             for p in referee_parts.jaw_part(recording.track, seen, fit, single)]
    parts += referee_parts.lips_part(recording.track)
    return parts, [row for p in parts for row in referee_rows.recording_rows(dataset, subject,
                                                                             task, p)]


def test_a_synthetic_slice_reproduces_the_generated_table(tmp_path_factory, generated, couplings):
    """S01 tp040 of the default corpus (the same file as the test corpus's) re-run: a
    change of the generator, the fits or the scoring makes the table stale and fails."""
    from cassi_fit.dataset import load_recording

    corpus = zoo.small_corpus(tmp_path_factory)
    recording = load_recording(next((corpus / "S01").glob("[Tt][Pp]040.[Tt][Xx][Yy]")))
    _, fresh = _slice(referee_parts.SYNTHETIC_LABEL, "S01", "tp040", recording, couplings)
    _compare(fresh, generated)


@pytest.mark.skipif(JW11 is None, reason=missing(XRMB_JW11))
def test_the_real_recording_reproduces_the_table_and_the_issues_hand_measurements(
        generated, couplings):
    import warnings

    from cassi_fit.dataset import Dataset

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # no Headmeasures: the default
        recording = Dataset(JW11).load("JW11", "tp005")
    parts, fresh = _slice(JW11.name, "JW11", "tp005", recording, couplings)
    _compare(fresh, generated)
    # issue 20's hand measurements (MNM from MNI, 724 frames): median (95th percentile)
    [mnm] = [p for p in parts if p.part == "jaw: MNM from MNI"]
    assert len(mnm.frames) == 723  # every tracked frame but the reference
    reproduced = {k: v for k, v in referee_parts.ISSUE_JW11.items() if not v[3]}
    assert len(reproduced) == 3
    for name, (_, median, p95, _) in reproduced.items():
        assert np.round(np.percentile(mnm.errors[name], [50, 95]), 1).tolist() == [median, p95]


def test_the_markdown_is_the_csv_rendered(generated, couplings):
    text = GENERATED_MD.read_text()
    first = text.splitlines()[0]
    assert first.startswith("<!-- written by `python experiments/real_referee.py ")
    assert "--docs docs/generated" in first
    command = first.split("`")[1]
    assert referee_report.markdown(generated, command, couplings) == text
    methods = {r["predictor"] for r in generated if r["role"] == "method"
               and r["part"].startswith("jaw")}
    assert methods == set(referee_parts.single_sensor_methods(lambda sensor: None))
    assert {r["dataset"] for r in generated} >= {referee_parts.SYNTHETIC_LABEL}
    if JW11 is not None:
        assert JW11.name in {r["dataset"] for r in generated}
        assert "one recording of one speaker" in text


def test_existing_outputs_are_kept_unless_forced(tmp_path, capsys):
    (tmp_path / "real_referee.csv").write_text("mine\n")
    data = tmp_path / "data"
    data.mkdir()
    assert real_referee.main([str(data), "--out", str(tmp_path)]) == 1
    assert "exists" in capsys.readouterr().err
    assert (tmp_path / "real_referee.csv").read_text() == "mine\n"
