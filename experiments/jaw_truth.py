"""The synthetic side of experiments/jaw_comparison.py: the noise families and regimes
compared, the truth (the true jaw motion, its fixed point) and each method's per-frame
errors against it, the recordings (one seed each) and smooth-pivot's tuning on held-out
subjects.
"""

from __future__ import annotations

import numpy as np

# name: (synth noise family, SD per coordinate in mm, unmarked jaw-pellet mistracks)
# ("xrmb": band-limited noise and the molar pellet's out-of-plane yaw at noise scale 1,
# docs/SYNTHETIC.md; its SD argument is the default noise, which it rescales itself)
NOISE_FAMILIES = {
    "none": ("white", 0.0, False),
    "white-0.25": ("white", 0.25, False),
    "drift-0.25": ("drift", 0.25, False),
    "xrmb": ("xrmb", 0.3 / np.sqrt(2.0), False),
    "mistracks": ("white", 0.25, True),
}


THETA_BINS_DEG = (0.0, 1.0, 2.0, 4.0, 8.0, 16.0, 90.0)


# Per-frame errors measured (column of frame_errors) ...
METRICS = ("pivot_err_mm", "angle_err_deg", "chin_err_mm", "incisor_err_mm")


# ... and the statistics reported per cell: key -> (per-frame error, percentile, title).
# The 95th percentile shows what a median hides: rare mistracks, occasional failures.
STATISTICS = {
    "median_pivot_err_mm": ("pivot_err_mm", 50, "pivot error (mm), median"),
    "median_angle_err_deg": ("angle_err_deg", 50, "angle error (deg), median"),
    "median_chin_err_mm": ("chin_err_mm", 50, "chin point error (mm), median"),
    "median_incisor_err_mm": ("incisor_err_mm", 50, "incisor tip error (mm), median"),
    "p95_chin_err_mm": ("chin_err_mm", 95, "chin point error (mm), 95th percentile"),
}


WINNER_STATISTICS = ("median_chin_err_mm", "median_pivot_err_mm", "median_angle_err_deg",
                     "p95_chin_err_mm")


N_SUBJECTS = 6  # per cell, each with its own geometry; x 2 tasks = 12 recordings per cell


BASE_SEED = 2026


TASKS = ("tp106", "tp040")  # jaw wagging (wide angles), a sentence (speech angles)


DURATION_S = 4.0


#: ``--small`` (the tests' run): one subject, one task, as long as the full run's recordings
#: (``DURATION_S``): the fits are compiled per frame count, so the small run, the full
#: run's cells that tests/test_experiment_jaw.py re-runs and the fits of its other tests
#: share their compilations
SMALL = {"subjects": 1, "tasks": ("tp106",), "duration_s": DURATION_S}


BOOTSTRAP, BOOTSTRAP_SEED = 400, 12345


TRUST_PIVOT_MM = 5.0  # a pivot is "trustworthy" when its median error is below this


MISTRACK_MM = (4.0, 10.0)  # jump size of an injected jaw-pellet mistrack


def _methods():
    from cassi_fit.options import JAW_METHODS

    return JAW_METHODS


# ------------------------------------------------------------------------ one recording
def _rotate(theta, points):
    """``R(theta) p`` (paper Eqs 4-5) for theta (n,) and points (n, 2) or (2,): (n, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    points = np.broadcast_to(points, (theta.shape[0], 2))
    return np.stack([c * points[:, 0] + s * points[:, 1], -s * points[:, 0] + c * points[:, 1]], -1)


def true_motion(truth, f0):
    """Per frame, the true motion from frame ``f0``: ``(theta (n,), t (n, 2), pivot (n, 2),
    defined (n,))``; ``current o reference^-1`` of the truth's poses from rest."""
    theta = truth.theta - truth.theta[f0]
    t = truth.translation - _rotate(theta, truth.translation[f0])
    one_minus_c, s = 1.0 - np.cos(theta), np.sin(theta)
    det = one_minus_c**2 + s**2  # det(I - R), 0 where there is no fixed point
    defined = det > 1e-18
    safe = np.where(defined, det, 1.0)
    pivot = np.stack([one_minus_c * t[:, 0] + s * t[:, 1], -s * t[:, 0] + one_minus_c * t[:, 1]],
                     -1) / safe[:, None]  # fmt: skip
    return theta, t, np.where(defined[:, None], pivot, np.nan), defined


def _with_mistracks(track, truth, rng):
    """The track with 1-3 unmarked mistracks on the jaw pellets (a jump of 4-10 mm of MNI
    or MNM for 1-5 frames), as ``rare mistracks``; the fits are not told."""
    from cassi_fit.txy import PelletTrack

    positions = track.positions.copy()
    tracked = np.flatnonzero(track.valid[:, 6:8].all(axis=(1, 2)))
    for _ in range(int(rng.integers(1, 4))):
        start = int(rng.choice(tracked[1:]))  # never the reference frame
        length = int(rng.integers(1, 6))
        angle = rng.uniform(0.0, 2 * np.pi)
        jump = rng.uniform(*MISTRACK_MM) * np.array([np.cos(angle), np.sin(angle)])
        positions[start : start + length, int(rng.integers(6, 8))] += jump
    return PelletTrack(times=track.times, positions=positions, valid=track.valid)


def frame_errors(track, truth, anatomy, method):  # method: an alias or a method object
    """Per-frame errors of one method on one recording: dict of (n,) arrays, NaN in the
    frames the method did not use (so methods are compared on the same frames)."""
    from cassi_fit.jaw_fit import fit_jaw
    from cassi_fit.status import fitted

    jaw = track.positions[:, 6:8, :]
    valid = track.valid[:, 6:8].all(axis=(1, 2))
    f0 = int(np.argmax(valid))
    options = {"solver": "optimistix-lm"} if isinstance(method, str) else {}
    fit = fit_jaw(jaw[f0], np.where(valid[:, None, None], jaw, 0.0), method=method,
                  valid=valid, **options)
    theta, t, pivot, defined = true_motion(truth, f0)
    use = valid & fitted(fit.status) & (np.arange(len(valid)) > f0)
    out = {"theta_deg": np.rad2deg(np.abs(theta)),
           "angle_err_deg": np.rad2deg(np.abs(fit.theta - theta))}  # fmt: skip
    est_pivot = np.where(fit.pivot_defined[:, None], fit.pivot, np.nan)
    out["pivot_err_mm"] = np.linalg.norm(est_pivot - pivot, axis=1)  # NaN: undefined
    for name, rest in (("incisor", anatomy.lower_incisor_tip_rest), ("chin", anatomy.chin_rest)):
        at_f0 = _rotate(truth.theta[f0 : f0 + 1], rest)[0] + truth.translation[f0]
        err = (_rotate(fit.theta, at_f0) + fit.translation) - (_rotate(theta, at_f0) + t)
        out[f"{name}_err_mm"] = np.linalg.norm(err, axis=1)
    return {k: v if k == "theta_deg" else np.where(use, v, np.nan) for k, v in out.items()}


def recording_seed(*names: str) -> tuple[int, int]:
    """A seed of its own for every recording, from its full names (e.g. family, subject,
    task): no two recordings share their noise or their task's random draws."""
    import zlib

    return BASE_SEED, zlib.crc32("|".join(names).encode())


def _recordings(small: bool, *, prefix: str = "X", tasks=None, noises=None, families=None):
    """Yield ``(family, noise name, recording id, track, truth, anatomy)`` for every
    recording. A subject's geometry is the same in every family (paired families); its
    motion and noise are drawn from the recording's own seed, shared by the noise levels
    of one recording (paired noise levels). ``prefix`` names the subjects (``X01`` ... for
    the comparison, ``H01`` ... for the held-out tuning set: other seeds, other people)."""
    from cassi_fit import synth

    n_subjects = SMALL["subjects"] if small else N_SUBJECTS
    tasks = tasks or (SMALL["tasks"] if small else TASKS)
    duration = SMALL["duration_s"] if small else DURATION_S
    for family in families or synth.JAW_KINEMATICS:
        for s in range(n_subjects):
            subject = f"{prefix}{s + 1:02d}"
            rng = np.random.default_rng(recording_seed(subject))
            anatomy = synth.make_subject(subject, rng, jaw_kinematics=family)
            for task in tasks:
                seed = recording_seed(family, subject, task)
                for noise, (kind, sd, mistracks) in NOISE_FAMILIES.items():
                    if noises is not None and noise not in noises:
                        continue
                    track, truth = synth.synth_recording(
                        anatomy, task, seed=seed, noise_mm=sd, duration_s=duration,
                        dropouts=False, mistracks=False, noise_family=kind)
                    if mistracks:
                        rng_m = np.random.default_rng((*seed, 8))
                        track = _with_mistracks(track, truth, rng_m)
                    yield family, noise, f"{subject}/{task}", track, truth, anatomy


# ------------------------------------------------------------------------------ tables
SMOOTHNESS_GRID = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0)


KNOT_SPACING_GRID = (4, 8, 16, 32)  # frames


TUNING_NOISES = ("white-0.25", "xrmb")


def tune_smooth_pivot(small: bool):
    """Choose smooth-pivot's ``smoothness`` and ``knot_spacing`` on held-out recordings.

    The held-out set: subjects ``H01`` ... (``N_SUBJECTS`` of them, not in the comparison),
    every truth family, both tasks, noises ``TUNING_NOISES``. Each pair of the grid
    ``SMOOTHNESS_GRID`` x ``KNOT_SPACING_GRID`` is scored by the median chin point error
    over all their frames; the lowest wins. Returns ``(rows, (smoothness, knot_spacing))``.
    With ``small`` nothing is tuned: the library's defaults, and no rows.
    """
    from cassi_fit.jaw_fit import DEFAULT_KNOT_SPACING, jaw_method

    if small:
        return [], (1.0, DEFAULT_KNOT_SPACING)
    recordings = list(_recordings(False, prefix="H", noises=TUNING_NOISES))
    rows = []
    for spacing in KNOT_SPACING_GRID:
        for smoothness in SMOOTHNESS_GRID:
            method = jaw_method("smooth-pivot", solver="optimistix-lm",
                                smoothness=smoothness, knot_spacing=spacing)
            chin, pivot = [], []
            for *_, track, truth, anatomy in recordings:
                errs = frame_errors(track, truth, anatomy, method)
                chin.append(errs["chin_err_mm"])
                pivot.append(errs["pivot_err_mm"])
            chin, pivot = np.concatenate(chin), np.concatenate(pivot)
            rows.append({"smoothness": smoothness, "knot_spacing": spacing,
                         "recordings": len(recordings),
                         "median_chin_err_mm": float(np.nanmedian(chin)),
                         "median_pivot_err_mm": float(np.nanmedian(pivot))})
    best = min(rows, key=lambda r: r["median_chin_err_mm"])
    return rows, (best["smoothness"], best["knot_spacing"])


def tuned_methods(choice):
    """name -> method object: smooth-pivot with the tuned ``(smoothness, knot_spacing)``."""
    from cassi_fit.jaw_fit import jaw_method

    smoothness, spacing = choice
    methods = default_methods()
    methods["smooth-pivot"] = jaw_method("smooth-pivot", solver="optimistix-lm",
                                         smoothness=smoothness, knot_spacing=spacing)
    return methods


def default_methods():
    """name -> method object, every alias with the library's defaults."""
    from cassi_fit.jaw_fit import jaw_method

    return {m: jaw_method(m, solver="optimistix-lm") for m in _methods()}
