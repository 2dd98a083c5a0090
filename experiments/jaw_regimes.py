"""The statistics of experiments/jaw_comparison.py: per regime (truth family x noise x
|theta| bin) the pooled statistics of the per-frame errors with bootstrap intervals
over recordings, the paired verdict that names a winner or a tie, and the angle up to
which the pivot is trustworthy.
"""

from __future__ import annotations

import numpy as np
from jaw_truth import (
    BOOTSTRAP,
    BOOTSTRAP_SEED,
    STATISTICS,
    THETA_BINS_DEG,
    TRUST_PIVOT_MM,
    WINNER_STATISTICS,
    _recordings,
    default_methods,
    frame_errors,
)


def _regimes(small: bool, methods=None):
    """``{(family, noise, bin lo): {method: [per-recording dict of (n_bin,) arrays]}}``,
    every method's arrays on the same frames of the same recordings."""
    methods = methods or default_methods()
    regimes: dict = {}
    for family, noise, _rec, track, truth, anatomy in _recordings(small):
        errs = {m: frame_errors(track, truth, anatomy, obj) for m, obj in methods.items()}
        theta = errs["closed-form"]["theta_deg"]  # the truth's, the same for every method
        for lo, hi in zip(THETA_BINS_DEG[:-1], THETA_BINS_DEG[1:], strict=True):
            sel = (theta >= lo) & (theta < hi)
            if not sel.any():
                continue
            cell = regimes.setdefault((family, noise, lo), {})
            for m, e in errs.items():
                cell.setdefault(m, []).append({k: v[sel] for k, v in e.items()})
    return regimes


def _stack(recs, metric, mask=None):
    """``(values, recording index)`` of ``metric`` pooled over the recordings ``recs``
    (finite values, and where ``mask`` (a list like ``recs``) is True)."""
    values, owner = [], []
    for i, r in enumerate(recs):
        keep = np.isfinite(r[metric]) if mask is None else mask[i]
        values.append(r[metric][keep])
        owner.append(np.full(int(keep.sum()), i))
    return np.concatenate(values), np.concatenate(owner)


def weighted_percentile(values, owner, counts, q):
    """The ``q``-th percentile (inverted CDF, as numpy's ``method="inverted_cdf"``) of the
    pooled ``values`` with each value weighted by ``counts[:, owner]``: one statistic per
    row of ``counts`` ``(B, n_recordings)`` (a bootstrap resample of the recordings is a
    count per recording). ``(B,)``; NaN where a resample holds no value."""
    order = np.argsort(values, kind="stable")
    v, w = values[order], counts[:, owner[order]].astype(float)  # (N,), (B, N)
    cum = np.cumsum(w, axis=1)
    total = cum[:, -1:] if cum.shape[1] else np.zeros((counts.shape[0], 1))
    target = q / 100.0 * total
    index = np.minimum((cum < target).sum(axis=1), max(v.shape[0] - 1, 0))
    out = v[index] if v.size else np.full(counts.shape[0], np.nan)
    return np.where(total[:, 0] > 0, out, np.nan)


def _resamples(n, rng):
    """``(BOOTSTRAP, n)`` counts: how often each of ``n`` recordings is drawn."""
    draws = rng.integers(0, n, size=(BOOTSTRAP, n))
    return np.stack([np.bincount(d, minlength=n) for d in draws])


def _interval(stats):
    stats = stats[np.isfinite(stats)]
    if not stats.size:
        return float("nan"), float("nan")
    lo, hi = np.percentile(stats, [2.5, 97.5])
    return float(lo), float(hi)


def synthetic_table(small: bool, methods=None):
    """``(rows, verdicts)``. Rows (dicts), one per method x family x noise x |theta| bin,
    with each of ``STATISTICS`` (key), its 95 % interval (key + ``_lo``, ``_hi``: a
    bootstrap over recordings, the independent units; frames of one recording share its
    noise and motion) and the recordings behind it. Verdicts:
    ``{(family, noise, bin lo, key): (text, clear winner or None)}`` (:func:`verdict`).
    ``methods``: name -> method object (default: the aliases with library defaults)."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    rows, verdicts = [], {}
    for (family, noise, lo), by_method in _regimes(small, methods).items():
        hi = THETA_BINS_DEG[THETA_BINS_DEG.index(lo) + 1]
        n = len(next(iter(by_method.values())))
        counts = _resamples(n, rng)
        for method, recs in by_method.items():
            row = {"method": method, "family": family, "noise": noise, "theta_lo_deg": lo,
                   "theta_hi_deg": hi, "recordings": n,
                   "frames": int(sum(np.isfinite(r["chin_err_mm"]).sum() for r in recs))}
            for key, (metric, q, _) in STATISTICS.items():
                values, owner = _stack(recs, metric)
                row[key] = (float(np.percentile(values, q, method="inverted_cdf"))
                            if values.size else float("nan"))
                row[f"{key}_lo"], row[f"{key}_hi"] = _interval(
                    weighted_percentile(values, owner, counts, q))
            rows.append(row)
        for key in WINNER_STATISTICS:
            metric, q, _ = STATISTICS[key]
            verdicts[(family, noise, lo, key)] = verdict(by_method, metric, q, counts)
    return rows, verdicts


def verdict(by_method, metric, q, counts):
    """``(text, winner)`` of one regime. The method with the lowest statistic wins only if,
    paired with every other method on the same frames, the 95 % interval of the difference
    of their statistics over the bootstrap resamples ``counts`` (recordings) lies below 0;
    otherwise the cell reads ``tie: A, B ...`` (the best and every method it does not
    beat) and the winner is None."""
    stats = {}
    for m, recs in by_method.items():
        values, _ = _stack(recs, metric)
        if values.size:
            stats[m] = float(np.percentile(values, q, method="inverted_cdf"))
    if not stats:
        return "-", None
    ranked = sorted(stats, key=stats.get)
    best = ranked[0]
    tied = []
    for m in ranked[1:]:
        a, b = by_method[best], by_method[m]
        both = [np.isfinite(x[metric]) & np.isfinite(y[metric]) for x, y in zip(a, b,
                                                                               strict=True)]
        va, oa = _stack(a, metric, both)
        vb, ob = _stack(b, metric, both)
        diff = weighted_percentile(va, oa, counts, q) - weighted_percentile(vb, ob, counts, q)
        if not _interval(diff)[1] < 0:
            tied.append(m)
    if tied:
        return "tie: " + ", ".join([best, *tied]), None
    return best, best


def trust_threshold(rows, method="closed-form", noise="white-0.25", family="physiological"):
    """Smallest |theta| (deg) from which every bin's median pivot error is < TRUST_PIVOT_MM."""
    bins = sorted((r for r in rows if r["method"] == method and r["noise"] == noise
                   and r.get("family", family) == family), key=lambda r: r["theta_lo_deg"])
    threshold = None
    for r in bins:
        if r["median_pivot_err_mm"] < TRUST_PIVOT_MM:
            threshold = r["theta_lo_deg"] if threshold is None else threshold
        else:
            threshold = None
    return threshold
