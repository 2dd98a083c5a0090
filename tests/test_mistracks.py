"""The mistrack detector on the shapes real trackers produce (issue 24, parts 1 and 7).

Every shape is injected by the experiment's injector (experiments/mistrack_detection.py,
built from the issue's description of the shapes, not from the detector's tests) into a
clean synthetic recording (always) and into the real JW11 recording (when
``shared/data/xrmb_jw11`` is found in a folder above the checkout; skipped with the reason
otherwise). Each test fails if the detector is removed (nothing flagged) or flags the
untouched data.
"""

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import zoo
from real_data import XRMB_JW11, missing, real_data  # noqa: E402

from cassi_fit.mistracks import Reason, detect, mistrack_report
from cassi_fit.pellets import MNI, MNM, T2, T3, first_valid_line
from cassi_fit.quality import quality_report
from cassi_fit.txy import PelletTrack, read_txy

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import mistrack_detection as experiment  # noqa: E402

JW11 = real_data(XRMB_JW11)


@pytest.fixture(scope="module")
def real():
    if JW11 is None:
        pytest.skip(missing(XRMB_JW11))
    return read_txy(JW11 / "jw11_tp005.txy")


@pytest.fixture(scope="module")
def synthetic():
    track, _ = zoo.sentence(clean=True)
    return track


@pytest.fixture(params=["synthetic", "real"])
def clean(request, synthetic):
    return synthetic if request.param == "synthetic" else request.getfixturevalue("real")


@pytest.fixture(scope="module")
def twin():
    """The real recording's synthetic twin, for the cases below that need real data's
    smoothness: the sentence with 0.02 mm of noise per coordinate, whose second
    differences' robust SD (0.05-0.10 mm per pellet) is JW11's (0.01-0.09 mm)."""
    track, _ = zoo.sentence(clean=True, noise_mm=0.02)
    return track


@pytest.fixture(params=["twin", "real"])
def smooth(request, twin):
    """Each case on real data (skipped without it) and on its synthetic twin (always)."""
    return twin if request.param == "twin" else request.getfixturevalue("real")


def _with(track: PelletTrack, positions: np.ndarray) -> PelletTrack:
    return PelletTrack(track.times, np.round(positions * 1e3) / 1e3, track.valid, track.path)


def _first_tracked(track: PelletTrack) -> int:
    return int(np.argmax(track.valid.all(axis=(1, 2))))


# ----------------------------------------------------------------- untouched data
def test_untouched_recordings_have_no_flags(clean):
    report = detect(clean)
    assert not report.flags.any(), report.counts()


def test_noise_free_stillness_is_no_plateau():
    """Without noise every synthetic pellet holds still at once for dozens of frames
    (rounded to the micrometre): that is no stuck tracker."""
    track, _ = zoo.sentence(clean=True, noise_mm=0.0)
    still = (np.diff(track.positions[20:], axis=0) == 0).all(axis=(1, 2))
    assert still.sum() > 20  # the premise: whole frames repeat exactly
    assert not detect(track).has(Reason.PLATEAU).any()


# ----------------------------------------------------------------- every shape
@pytest.mark.parametrize("shape, reason, least", [
    ("spike", Reason.JUMP, 1.0),
    ("zero-dropout", Reason.DROPOUT, 1.0),
    ("marker-dropout", Reason.DROPOUT, 1.0),
    ("stuck", Reason.PLATEAU, 1.0),
    ("persistent-jump", Reason.PERSISTENT_JUMP, 1.0),
    ("swap", Reason.SWAP, 1.0),
    ("first-line spike", Reason.EDGE, 0.6),
    ("last-line spike", Reason.EDGE, 0.6),
])
def test_each_shape_is_flagged_with_its_reason(clean, shape, reason, least):
    """Six injections per shape: the share of injected values flagged (all of them, or
    for 2-8 mm edge spikes on noisy synthetic data most), with the shape's reason, and
    almost nothing else."""
    rng = np.random.default_rng(7)
    hit = total = with_reason = other = 0
    for _ in range(6):
        track, truth, _ = experiment.inject(clean, shape, rng)
        report = detect(track)
        hit += (report.flags & truth).sum()
        with_reason += (report.has(reason) & truth).sum()
        total += truth.sum()
        other += (report.flags & ~truth).sum()
    assert hit >= least * total
    assert with_reason >= least * total
    assert other <= 6 * 2  # e.g. the first value of a stuck run, a spike's neighbour


def _drift_along_the_jaw(track: PelletTrack, pellet: int, start: int) -> PelletTrack:
    """``pellet`` slides 10 mm over 100 frames along the jaw line (MNM to MNI), then
    snaps back: a drift the rigid jaw distance can see (across the line it cannot: a
    two-pellet jaw would then just rotate about the other pellet; docs/FORMATS.md)."""
    pos = track.positions.copy()
    line = np.nanmedian(pos[:, MNI] - pos[:, MNM], axis=0)
    pos[start:start + 100, pellet] += np.linspace(0.1, 10.0, 100)[:, None] * line / np.hypot(*line)
    return _with(track, pos)


@pytest.mark.parametrize("pellet", [MNI, MNM])
def test_drift_of_a_jaw_pellet_is_seen_by_the_rigid_jaw(clean, pellet):
    """10 mm over 100 frames: invisible to every speed test, seen by the jaw distance
    once it passes 2 mm (at most about 80 of the 100 values), on both jaw pellets."""
    start = _first_tracked(clean) + 200
    report = detect(_drift_along_the_jaw(clean, pellet, start))
    seen = report.flags[start:start + 100, pellet]
    assert seen.sum() >= 60 and seen[-40:].all()
    assert report.has(Reason.DRIFT)[start + 99, pellet]
    assert report.has(Reason.JAW_DISTANCE)[start + 99, pellet]
    outside = report.flags.copy()
    outside[start:start + 100, [MNI, MNM]] = False
    assert not outside.any()


# ----------------------------------------------------------------- the cases
def test_mni_at_the_incisor_tip_for_20_frames_is_mistracked_everywhere(smooth):
    """Issue 24: MNI set to (0, 0) for 20 frames passed as ``ok`` (theta -15 degrees)."""
    pos = smooth.positions.copy()
    pos[300:320, MNI] = 0.0
    track = _with(smooth, pos)
    report = mistrack_report(track)
    assert report is track.mistracks  # the one detection, kept on the track
    assert report.has(Reason.DROPOUT)[300:320, MNI].all()
    assert report.flags.sum() == 20
    assert quality_report(track).n_mistracked["MNI"] == 20
    assert quality_report(track).mistrack_reasons["MNI"]["dropout"] == 20
    from cassi_fit.gaps import bad_values
    from cassi_fit.jaw_fit import jaw_from_track
    from cassi_fit.status import Status

    assert bad_values(track)[1][300:320, MNI].all()
    status = jaw_from_track(track).status
    assert (status[300:320] == Status.MISTRACKED).all()
    assert (status[290:300] == Status.OK).all()


def test_mni_stuck_for_40_frames_is_a_plateau(smooth):
    pos = smooth.positions.copy()
    pos[300:340, MNI] = pos[300, MNI]
    report = detect(_with(smooth, pos))
    assert report.has(Reason.PLATEAU)[300:340, MNI].all()
    assert report.flags.sum() == 40


def test_slow_drift_of_mni_across_the_jaw_line_is_not_seen(smooth):
    """The limit stated in docs/FORMATS.md: MNI sliding 10 mm down while MNM
    stays is, to two pellets, the jaw rotating about MNM; the rigid distance changes by
    about 2 mm at the end. If this starts to fail, the detector has learned to see it:
    update the documentation. (Down, perpendicular to the recording's own jaw line: the
    twin's rises toward MNM more steeply than JW11's.)"""
    pos = smooth.positions.copy()
    line = np.nanmedian(pos[:, MNI] - pos[:, MNM], axis=0)
    down = np.array([line[1], -line[0]]) / np.hypot(*line)
    pos[300:400, MNI] += np.linspace(0.1, 10.0, 100)[:, None] * down
    assert detect(_with(smooth, pos)).flags[300:390].sum() == 0


@pytest.mark.parametrize("where", ["first", "last"])
def test_a_spike_on_the_first_or_last_line(smooth, where):
    k = _first_tracked(smooth) if where == "first" else smooth.n_frames - 1
    pos = smooth.positions.copy()
    pos[k, MNI] += [0.0, 3.0]
    track = _with(smooth, pos)
    report = detect(track)
    assert report.has(Reason.EDGE)[k, MNI]
    assert report.flags.sum() == 1
    if where == "first":
        with pytest.warns(UserWarning, match="moved to data line"):
            assert first_valid_line(track).index == k + 1


def test_t2_and_t3_swapped_for_20_frames(smooth):
    pos = smooth.positions.copy()
    pos[300:320, [T2, T3]] = pos[300:320, [T3, T2]]
    report = detect(_with(smooth, pos))
    assert report.has(Reason.SWAP)[300:320][:, [T2, T3]].all()
    assert report.flags.sum() == 40


def test_a_sub_millimetre_spike_is_flagged(smooth):
    """Smooth data show spikes far below any speed limit: one value off its neighbours'
    midpoint by h needs the acceleration 2 h / dt^2, so the documented limit
    (``MAX_ACCELERATION_MM_S2`` plus ``NOISE_SDS`` times the pellet's noise, the robust SD
    of its second differences) flags h above half of ``limit dt^2``. Spikes of 0.58 of
    that (under 1 mm here; nothing else in the detector sees them) on MNI's stillest
    frames are flagged, as a jump, and nothing else is."""
    from cassi_fit.mistracks import MAX_ACCELERATION_MM_S2, NOISE_SDS

    pos = smooth.positions.copy()
    dt = float(np.median(np.diff(smooth.times)))
    d2 = pos[2:, MNI] - 2.0 * pos[1:-1, MNI] + pos[:-2, MNI]
    mad = np.nanmedian(np.abs(d2 - np.nanmedian(d2, axis=0)), axis=0)
    noise = float(np.hypot(*(1.4826 * mad)))
    h = 0.58 * (MAX_ACCELERATION_MM_S2 * dt**2 + NOISE_SDS * noise)
    assert h < 1.0
    bend = np.linalg.norm(d2, axis=1)
    at = []
    for k in np.argsort(bend[200:500]) + 201:  # the stillest, 20 frames apart
        if all(abs(k - j) > 20 for j in at):
            at.append(int(k))
        if len(at) == 4:
            break
    pos[at, MNI, 1] += h
    report = detect(_with(smooth, pos))
    assert report.has(Reason.JUMP)[at, MNI].all(), (h, at)
    assert report.flags.sum() == len(at)


def test_the_jaw_pellets_trading_places(synthetic):
    pos = synthetic.positions.copy()
    pos[200:220, [MNI, MNM]] = pos[200:220, [MNM, MNI]]
    report = detect(_with(synthetic, pos))
    assert report.flags[200:220][:, [MNI, MNM]].all()
    assert report.has(Reason.SWAP)[200:220][:, [MNI, MNM]].all()
    assert report.flags.sum() == 40


def test_a_still_pellet_in_a_moving_recording_is_a_plateau_but_not_a_short_one(synthetic):
    pos = synthetic.positions.copy()
    pos[200:207, T3] = pos[200, T3]  # 7 frames: below PLATEAU_FRAMES
    assert not detect(_with(synthetic, pos)).has(Reason.PLATEAU).any()
    pos[200:208, T3] = pos[200, T3]  # 8 frames
    assert detect(_with(synthetic, pos)).has(Reason.PLATEAU)[200:208, T3].all()


def test_untracked_values_are_never_flagged(synthetic):
    valid = synthetic.valid.copy()
    pos = synthetic.positions.copy()
    pos[100:120, T2] = 0.0  # a dropout to zero ...
    valid[100:120, T2] = False  # ... but marked untracked
    report = detect(PelletTrack(synthetic.times, pos, valid))
    assert not report.flags.any()


def test_reasons_are_words_and_counts(synthetic):
    pos = synthetic.positions.copy()
    pos[150:170, MNM] = 0.0
    report = detect(_with(synthetic, pos))
    assert report.counts()["MNM"] == {"dropout": 20}
    labels = report.frame_labels()
    assert labels[150] == "MNM:dropout" and labels[149] == ""
    assert Reason.PERSISTENT_JUMP.label == "persistent-jump"


def test_degenerate_tracks_do_not_fail():
    for n in (0, 1, 2, 3):
        t = np.arange(n) * 6866e-6
        pos = np.tile(zoo.sentence(clean=True)[0].positions[30], (n, 1, 1))
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            report = detect(PelletTrack(t, pos, np.ones((n, 8, 2), bool)))
        assert report.reasons.shape == (n, 8)


# ----------------------------------------------------------------- reports and the experiment
def test_cassi_info_counts_per_pellet_and_reason(tmp_path, capsys, synthetic):
    import json
    import wave

    from cassi_fit.cli import main
    from cassi_fit.txy import write_txy

    pos = synthetic.positions.copy()
    pos[200:220, MNI] = 0.0
    pos[300:340, T3] = pos[300, T3]
    path = write_txy(tmp_path / "S01_tp040.txy", _with(synthetic, pos))
    with wave.open(str(tmp_path / "S01_tp040.wav"), "wb") as out:  # 1.8 s: a 44.1 kHz header
        out.setnchannels(1), out.setsampwidth(2), out.setframerate(44100)
        out.writeframes(np.zeros(int(16000 * synthetic.times[-1]), np.int16).tobytes())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # default head measures
        assert main(["info", str(path)]) == 0
        text = capsys.readouterr().out
        assert main(["info", str(path), "--json"]) == 0
    lines = {line.split()[0]: line for line in text.splitlines() if line.startswith("  ")}
    assert lines["MNI"].split()[2:] == ["20", "dropout", "20"]
    assert lines["T3"].split()[2:] == ["40", "plateau", "40"]
    assert lines["UL"].split()[2:] == ["0"]
    assert "the header's rate is likely wrong: the samples fill the recording at 16000 Hz" in text
    report = json.loads(capsys.readouterr().out)
    assert report["quality"]["mistrack_reasons"]["MNI"] == {"dropout": 20}
    assert report["sound"]["status"] == "rate"


def test_the_experiment_writes_its_tables(tmp_path):
    assert experiment.main(["--small", "--trials", "2", "--docs", str(tmp_path)]) == 0
    text = (tmp_path / experiment.DOCS_NAME).read_text()
    assert text.startswith(f"<!-- written by `{experiment.MAKE_COMMAND}`")
    assert "| zero-dropout | 2 | 40 | 100.0 |" in text
    assert ("one recording of one speaker" in text) == (JW11 is not None)
    assert "## False alarms" in text
    assert experiment.main(["--small", "--trials", "2", "--docs", str(tmp_path)]) == 1  # exists
