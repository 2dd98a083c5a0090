"""Priors for the jaw fits with one jaw sensor: where the pivot is, and how the rotation is
coupled to the sensor's displacement.

With one jaw sensor the data cannot determine the jaw's rotation: one point's position fixes
two of a planar rigid motion's three parameters (theta, tx, ty), and the third comes from a
model. A pivot model gets it from the curvature of the sensor's path, which in speech is a
short, nearly straight arc: a pivot fitted freely to the lower incisor alone of the real
XRMB recording JW11 lands 27 mm behind the incisors and predicts the molar pellet with a
7.3 mm median error (issue 20). So the pivot methods take a :class:`PivotPrior` (a mean and
an SD, as extra residuals), and :class:`~cassi_fit.jaw_fit.CoupledRotation` takes the
rotation from a :class:`JawCoupling`: theta as a linear function of the sensor's
displacement, learned from two-sensor recordings (:func:`~cassi_fit.jaw_fit.learn_jaw_coupling`).
Each fit states the prior it used (``JawFit.prior``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Pellet noise (mm per coordinate) assumed where a fit has no residual to estimate it
#: from: XRMB's, about 0.3 mm (the jaw-pellet distance SD of the real JW11 recording is
#: 0.30 mm). A pivot prior's first pass weighs the data with it.
PRIOR_NOISE_MM = 0.3


@dataclass(frozen=True)
class PivotPrior:
    """A prior on the jaw pivot: ``mean_mm`` (2,) in the pellet frame (origin at the upper
    incisor tip, +x forward, +y up), ``sd_mm`` (2,) per axis (``inf``: no prior, the pivot
    estimated from the data), ``source`` (where the numbers come from).

    Added to a fit as the residuals ``(s / sd_mm) * (q - mean_mm)`` (mm), ``s`` the data's
    noise, so that the cost is the negative log posterior times ``s^2``. The data's weight
    is that of their independent information: a first pass (``s`` =
    :data:`PRIOR_NOISE_MM`) gives the residuals, whose rms and frame-to-frame correlation
    ``rho`` give ``s^2 = rms^2 (1 + rho) / (1 - rho)`` for the second. A pivot model that
    misses the jaw's translation leaves residuals that persist for many frames; counted as
    independent pellet noise they would outweigh any prior.
    """

    mean_mm: tuple[float, float]
    sd_mm: tuple[float, float]
    source: str

    def __post_init__(self):
        mean = tuple(float(v) for v in self.mean_mm)
        sd = tuple(float(v) for v in self.sd_mm)
        if len(mean) != 2 or len(sd) != 2 or not all(math.isfinite(v) for v in mean):
            raise ValueError(f"pivot prior: mean_mm must be 2 finite numbers, got {self.mean_mm}")
        if not all(v > 0 for v in sd):
            raise ValueError(f"pivot prior: sd_mm must be > 0, got {self.sd_mm}")
        object.__setattr__(self, "mean_mm", mean)
        object.__setattr__(self, "sd_mm", sd)

    @property
    def informative(self) -> bool:
        """False for the no-prior :data:`PIVOT_FROM_DATA`."""
        return any(math.isfinite(v) for v in self.sd_mm)

    def weight(self, noise_mm: float) -> tuple[float, float]:
        """``noise_mm / sd_mm`` per axis (0 where there is no prior)."""
        return tuple(noise_mm / v for v in self.sd_mm)

    def describe(self) -> str:
        """One line for tables: the source, the mean and the SD."""
        if not self.informative:
            return self.source
        (x, y), (sx, sy) = self.mean_mm, self.sd_mm
        return (f"pivot prior ({x:g}, {y:g}) mm, SD ({sx:g}, {sy:g}) mm: {self.source}")


#: No prior: the pivot estimated from the data alone (the two-sensor default).
PIVOT_FROM_DATA = PivotPrior((0.0, 0.0), (math.inf, math.inf), "pivot estimated from the data")

#: The population condyle: the mandibular condyle about 90-100 mm behind and 20-30 mm above
#: the upper incisor tip (docs/JAW.md; the face model's anatomy notes; the synthetic
#: subjects' norms), with an SD of 15 mm per axis for speakers' sizes and the condyle's
#: slide. The one-sensor default of the pivot methods. On the real JW11 recording the
#: two-pellet fits put the effective pivot far lower (about 138 mm behind, 24 mm below):
#: see docs/generated/single_sensor_jaw.md before relying on it.
POPULATION_CONDYLE = PivotPrior(
    (-95.0, 25.0), (15.0, 15.0),
    "population condyle, 90-100 mm behind and 20-30 mm above the upper incisor tip "
    "(docs/JAW.md)")


@dataclass(frozen=True)
class JawCoupling:
    """The jaw rotation as a linear function of one jaw sensor's displacement:
    ``theta = rad_per_mm . (p' - p_ref)`` (rad; the displacement in mm from the reference
    frame, in the pellet frame).

    sensor: the sensor whose displacement drives it (``"MNI"`` or ``"MNM"``).
    theta_sd_rad: the scatter of the two-sensor theta about the line in the recordings it
    was learned from (within a speaker). rad_per_mm_sd (2,): the spread of the coefficients
    between sources (how much another speaker may differ), per component. frames: how many
    frames it was learned from. source: where it was learned. A fit's uncertainty of theta
    in a frame with displacement ``d`` is ``theta_sd_rad^2 + sum (rad_per_mm_sd * d)^2``.
    """

    sensor: str
    rad_per_mm: tuple[float, float]
    theta_sd_rad: float
    rad_per_mm_sd: tuple[float, float]
    frames: int
    source: str

    def __post_init__(self):
        if self.sensor not in ("MNI", "MNM"):
            raise ValueError(f"jaw coupling: sensor must be MNI or MNM, got {self.sensor!r}")
        object.__setattr__(self, "rad_per_mm", tuple(float(v) for v in self.rad_per_mm))
        object.__setattr__(self, "rad_per_mm_sd", tuple(float(v) for v in self.rad_per_mm_sd))

    def describe(self) -> str:
        """One line for tables: the coefficients and the source."""
        (ax, ay) = self.rad_per_mm
        return (f"coupling theta = {ax:.5f} dx + {ay:.5f} dy rad/mm of {self.sensor}'s "
                f"displacement, learned from {self.source} ({self.frames} frames)")


#: The default couplings, learned by ``learn_jaw_coupling`` from the real XRMB recording
#: JW11 task 5 (one speaker; experiments/single_sensor_jaw.py derives these numbers and
#: tests/test_jaw_single_sensor.py checks them against the recording when it is present).
#: The coefficient SD is the difference between this coupling and the one learned from
#: the synthetic corpus's families not tuned to JW11 (docs/generated/single_sensor_jaw.md):
#: a stand-in for the spread between speakers, which one speaker cannot measure.
_JW11 = "the real XRMB recording JW11 task 5 (one speaker)"
DEFAULT_COUPLINGS: dict[str, JawCoupling] = {
    "MNI": JawCoupling("MNI", (-0.00616384, -0.00748067), 0.00559477, (0.00075, 0.00087), 724,
                       _JW11),
    "MNM": JawCoupling("MNM", (-0.00838916, -0.0117919), 0.00839470, (0.00288, 0.00008), 724,
                       _JW11),
}
