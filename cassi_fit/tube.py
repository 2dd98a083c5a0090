"""The vocal tract as a lossy acoustic tube: transfer function and formants (JAX).

A frame's tract is a chain of ``n`` cylindrical sections, glottis first, each with an area
(mm^2) and a length (mm). Each section is a lossy transmission line (Sondhi & Schroeter
1987, "A hybrid time-frequency domain articulatory speech synthesizer", IEEE Trans. ASSP
35(7):955-967, their chain (ABCD) matrix of a uniform lossy section):

* series impedance per unit length ``Z = j w rho / A + R``, with the viscous loss at the
  wall ``R = S sqrt(w rho mu / 2) / A^2`` (``S`` the section's perimeter, of a circle);
* shunt admittance per unit length ``Y = j w A / (rho c^2) + G + Y_wall``, with the thermal
  loss ``G = S (eta - 1) / (rho c^2) sqrt(lambda w / (2 c_p rho))`` (Fant 1960, Flanagan
  1972 Eqs 3.33-3.34) and the yielding wall ``Y_wall = S / (j w m + b + k / (j w))`` with
  ``m = 1.5 g/cm^2``, ``b = 1600 dyn s/cm^3``, ``k = 3e5 dyn/cm^3`` (the soft-tissue wall
  values of Maeda 1982, Speech Commun. 1:199-229, after Ishizaka, French & Flanagan 1975);
* the section's matrix ``[[cosh(g l), Zc sinh(g l)], [sinh(g l) / Zc, cosh(g l)]]`` with
  ``g = sqrt(Z Y)``, ``Zc = sqrt(Z / Y)``; ``[P, U]`` at the glottis = product of the
  matrices x ``[P, U]`` at the lips.

The lips radiate into a piston-in-an-infinite-baffle load (Flanagan 1972, Eq. 3.41: a
resistance ``128 rho c / (9 pi^2 A)`` in parallel with an inertance ``8 rho / (3 pi
sqrt(pi A))``). The transfer function is the volume velocity at the lips over the one at
the glottis (an ideal flow source), ``H = 1 / (C Z_rad + D)``.

Formants are the peaks of ``|H|`` below ``F_MAX_HZ``: found on a frequency grid as the
minima of ``q = |1/H|^2``, refined by Newton's method on ``dq/df = 0`` (``q'`` and ``q''`` by central
differences of 0.5 Hz, O(0.5^2) accurate), and made
differentiable by the implicit function theorem (the last step carries the gradient
``df*/dtheta = -q'_theta / q''``; nothing of the grid's argmin reaches the gradient). A
bandwidth is the 3-dB width of a single resonance with the dip's depth and curvature,
``B = sqrt(8 q / q'')``. A formant not found
below ``F_MAX_HZ`` is NaN (documented: an area function with fewer than four resonances in
range, e.g. a very short tract).

Units at the interface: mm, mm^2, Hz; inside, CGS (cm, g, s) as the constants are
published.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

#: Speed of sound in warm moist air (cm/s) and its density (g/cm^3): body-temperature air
#: (Flanagan 1972, Table 3.1 uses 35,400 cm/s and 1.14e-3 g/cm^3 at 37 C, saturated).
C_CM_S = 35400.0
RHO = 1.14e-3
MU = 1.86e-4        # viscosity, g/(cm s)
LAMBDA = 5.5e-5     # heat conduction, cal/(cm s C)
C_P = 0.24          # specific heat at constant pressure, cal/(g C)
ETA = 1.4           # adiabatic constant
WALL_MASS = 1.5     # g/cm^2
WALL_RESISTANCE = 1600.0   # dyn s/cm^3
WALL_STIFFNESS = 3.0e5     # dyn/cm^3

#: Story (2008, JASA 123:327-335), the 2002 male speaker's MRI area functions of /i a u/:
#: ``vowel: (section length cm, areas cm^2 glottis first)``. The tests run them through the
#: tube; ``experiments/acoustic_tract_diagnosis.py`` sets the model's vowels beside them.
STORY_2008 = {
    "i": (0.384, [0.51, 0.59, 0.62, 0.72, 1.24, 2.30, 3.30, 3.59, 3.22, 2.86, 3.00, 3.61, 4.39,
                  4.95, 5.17, 5.16, 5.18, 5.26, 5.20, 5.02, 4.71, 4.13, 3.43, 2.83, 2.32, 1.83,
                  1.46, 1.23, 1.08, 0.94, 0.80, 0.67, 0.55, 0.46, 0.40, 0.36, 0.35, 0.35, 0.38,
                  0.51, 0.74, 0.92, 0.96, 0.91]),
    "a": (0.388, [0.56, 0.62, 0.66, 0.78, 0.97, 1.16, 1.12, 0.82, 0.55, 0.45, 0.37, 0.29, 0.21,
                  0.15, 0.16, 0.25, 0.34, 0.43, 0.54, 0.61, 0.67, 0.98, 1.76, 2.75, 3.52, 4.08,
                  4.74, 5.61, 6.60, 7.61, 8.48, 9.06, 9.29, 9.26, 9.06, 8.64, 7.91, 6.98, 6.02,
                  5.13, 4.55, 4.52, 4.71, 4.72]),
    "u": (0.445, [0.54, 0.61, 0.66, 0.75, 1.13, 1.99, 2.83, 2.90, 2.52, 2.40, 2.83, 3.56, 3.99,
                  3.89, 3.50, 3.04, 2.64, 2.44, 2.31, 2.07, 1.80, 1.52, 1.14, 0.74, 0.42, 0.22,
                  0.14, 0.20, 0.47, 0.89, 1.15, 1.42, 2.17, 3.04, 3.69, 4.70, 5.74, 5.41, 3.82,
                  2.34, 1.35, 0.65, 0.29, 0.16]),
}
#: Peterson & Barney (1952, JASA 24:175-184), men's average F1, F2, F3 (Hz)
PETERSON_BARNEY_MEN = {"i": (270, 2290, 3010), "a": (730, 1090, 2440), "u": (300, 870, 2240)}

#: The formant search's range and grid (Hz): four formants of an adult tract lie below it.
F_MIN_HZ = 80.0
F_MAX_HZ = 5000.0
GRID_STEP_HZ = 10.0
N_FORMANTS = 4
NEWTON_STEPS = 4
#: The central differences' step (Hz) for q' and q'' (their error is O(step^2)).
FD_STEP_HZ = 0.5


class Losses(NamedTuple):
    """Which losses are on: each a weight, 1 (on) or 0 (off), a bool or an array (a pytree:
    switching them does not recompile). The closed forms are checked with them off."""

    viscous: bool = True
    thermal: bool = True
    wall: bool = True
    radiation: bool = True


LOSSLESS = Losses(False, False, False, False)
ALL_LOSSES = Losses()


class Formants(NamedTuple):
    """``frequency`` and ``bandwidth`` ``(..., N_FORMANTS)`` Hz, lowest first (NaN where
    fewer resonances lie below ``F_MAX_HZ``)."""

    frequency: Float[Array, "... 4"]
    bandwidth: Float[Array, "... 4"]


def _section_matrices(w, area_cm2, length_cm, losses: Losses):
    """The chain matrix entries ``(a, b, c, d)`` of every section at angular frequency
    ``w`` (rad/s), each ``(n,)`` complex."""
    j = 1j
    perimeter = 2.0 * jnp.sqrt(jnp.pi * area_cm2)
    z = j * w * RHO / area_cm2
    y = j * w * area_cm2 / (RHO * C_CM_S**2)
    z = z + losses.viscous * perimeter * jnp.sqrt(w * RHO * MU / 2.0) / area_cm2**2
    y = y + losses.thermal * perimeter * (ETA - 1.0) / (RHO * C_CM_S**2) * jnp.sqrt(
        LAMBDA * w / (2.0 * C_P * RHO))
    y = y + losses.wall * perimeter / (j * w * WALL_MASS + WALL_RESISTANCE + WALL_STIFFNESS / (j * w))
    gamma = jnp.sqrt(z * y)
    zc = jnp.sqrt(z / y)
    gl = gamma * length_cm
    ch, sh = jnp.cosh(gl), jnp.sinh(gl)
    return ch, zc * sh, sh / zc, ch


def _radiation(w, area_cm2):
    """Flanagan's piston in an infinite baffle: R in parallel with an inertance."""
    r = 128.0 * RHO * C_CM_S / (9.0 * jnp.pi**2 * area_cm2)
    inert = 8.0 * RHO / (3.0 * jnp.pi * jnp.sqrt(jnp.pi * area_cm2))
    jwl = 1j * w * inert
    return jwl * r / (r + jwl)


def _mul(m, k):
    """``m @ k`` for 2x2 matrices stored as ``(a, b, c, d)`` tuples of arrays."""
    return (m[0] * k[0] + m[1] * k[2], m[0] * k[1] + m[1] * k[3],
            m[2] * k[0] + m[3] * k[2], m[2] * k[1] + m[3] * k[3])


def _chain_product(m):
    """The ordered product of the section matrices ``m = (a, b, c, d)``, each ``(n,)``,
    section 0 (the glottis) on the left."""
    eye = (jnp.ones((), m[0].dtype), jnp.zeros((), m[0].dtype),
           jnp.zeros((), m[0].dtype), jnp.ones((), m[0].dtype))
    total, _ = jax.lax.scan(lambda acc, k: (_mul(acc, k), None), eye, m)
    return total


def transfer(
    frequency_hz: Float[ArrayLike, ""], areas_mm2: Float[ArrayLike, " n"],
    lengths_mm: Float[ArrayLike, " n"], losses: Losses = ALL_LOSSES,
) -> Array:
    """The complex volume-velocity transfer function lips/glottis at one frequency (Hz) of
    the tract ``areas_mm2 (n,)``, ``lengths_mm (n,)`` (glottis first). vmap for many."""
    w = 2.0 * jnp.pi * jnp.asarray(frequency_hz)
    area = jnp.asarray(areas_mm2) / 100.0
    length = jnp.asarray(lengths_mm) / 10.0
    a, b, c, d = _section_matrices(w, area, length, losses)

    total = _chain_product((a, b, c, d))
    z_rad = losses.radiation * _radiation(w, area[-1])
    return 1.0 / (total[2] * z_rad + total[3])



def log_gain(frequency_hz, areas_mm2, lengths_mm, losses: Losses = ALL_LOSSES):
    """``log |H|^2`` at one frequency (real; the function whose peaks are the formants)."""
    h = transfer(frequency_hz, areas_mm2, lengths_mm, losses)
    return jnp.log(jnp.real(h) ** 2 + jnp.imag(h) ** 2)


def spectrum(
    frequencies_hz: Float[ArrayLike, " k"], areas_mm2: Float[ArrayLike, " n"],
    lengths_mm: Float[ArrayLike, " n"], losses: Losses = ALL_LOSSES,
) -> Float[Array, " k"]:
    """``20 log10 |H|`` (dB) at ``frequencies_hz (k,)``."""
    g = jax.vmap(lambda f: log_gain(f, areas_mm2, lengths_mm, losses))(jnp.asarray(frequencies_hz))
    return 10.0 * g / jnp.log(10.0)


def _grid(dtype, step=GRID_STEP_HZ):
    return jnp.arange(F_MIN_HZ, F_MAX_HZ + step / 2, step, dtype=dtype)


def _inverse_gain(frequency_hz, areas_mm2, lengths_mm, losses):
    """``|1 / H|^2`` at one frequency: near a resonance ``kappa ((f - F)^2 + (B / 2)^2)``, a
    parabola (where ``log |H|^2`` is concave only within ``B / 2`` of the peak), so Newton's
    method on its derivative converges from a grid point even for a narrow peak, and the
    lossless tube's poles are its zeros."""
    h = transfer(frequency_hz, areas_mm2, lengths_mm, losses)
    return 1.0 / (jnp.real(h) ** 2 + jnp.imag(h) ** 2)


def formants(
    areas_mm2: Float[ArrayLike, " n"], lengths_mm: Float[ArrayLike, " n"],
    losses: Losses = ALL_LOSSES, grid_step_hz: float = GRID_STEP_HZ,
) -> Formants:
    """F1-F4 and their bandwidths (Hz) of one tract (module docstring); differentiable in
    the areas and lengths. vmap over frames. ``grid_step_hz`` (static): the search grid's
    step; Newton's steps refine from it (a coarser grid is cheaper, and misses only
    resonances closer together than about two steps)."""
    areas = jnp.asarray(areas_mm2)
    lengths = jnp.asarray(lengths_mm)
    dtype = jnp.result_type(areas.dtype, lengths.dtype, float)
    grid = _grid(dtype, grid_step_hz)
    consts = jax.lax.stop_gradient((areas, lengths))
    q = jax.vmap(lambda f: _inverse_gain(f, *consts, losses))(grid)
    dip = (q[1:-1] < q[:-2]) & (q[1:-1] <= q[2:])
    (idx,) = jnp.nonzero(dip, size=N_FORMANTS, fill_value=-1)
    found = idx >= 0
    start = grid[jnp.where(found, idx + 1, 0)]

    # derivatives in f by forward mode (cheaper to compile under an outer reverse pass)
    def slopes(f, a, ln):
        """``q'`` and ``q''`` at ``f`` by central differences of step ``FD_STEP_HZ`` (three
        evaluations; no derivative in ``f`` for the compiler to build)."""
        qs = jax.vmap(lambda x: _inverse_gain(x, a, ln, losses))(f + FD_STEP_HZ * jnp.arange(-1.0, 2.0, dtype=dtype))
        return (qs[2] - qs[0]) / (2 * FD_STEP_HZ), (qs[2] - 2 * qs[1] + qs[0]) / FD_STEP_HZ**2, qs[1]

    def refine(f0):
        def step(f, _):
            d1, d2, _ = slopes(f, *consts)
            # a Newton step that would leave the grid cell's neighbourhood is clipped
            s = jnp.where(d2 > 0, d1 / jnp.where(d2 > 0, d2, 1.0), 0.0)
            return f - jnp.clip(s, -grid_step_hz, grid_step_hz), None

        f, _ = jax.lax.scan(step, f0, None, length=NEWTON_STEPS)
        f = jax.lax.stop_gradient(f)
        d1, d2, q = slopes(f, areas, lengths)
        curvature = jax.lax.stop_gradient(d2)
        ok = curvature > 0
        # the implicit-function step: value f (q' = 0 there), gradient -q'_theta / q''
        f_star = f - jnp.where(ok, d1 / jnp.where(ok, curvature, 1.0), 0.0)
        # q = kappa ((f - F)^2 + (B/2)^2): B = sqrt(8 q(F) / q''(F)); a minimum has
        # q'' > 0 (the double where keeps a flat point's NaN out of the gradient)
        ratio = q / jnp.where(ok, d2, 1.0)
        bandwidth = jnp.where(ok, jnp.sqrt(8.0 * jnp.where(ok, jnp.maximum(ratio, 0.0), 1.0)), jnp.nan)
        return f_star, bandwidth

    freq, bw = jax.vmap(refine)(start)
    nan = jnp.asarray(jnp.nan, dtype)
    return Formants(jnp.where(found, freq, nan), jnp.where(found, bw, nan))


@jax.jit
def formants_batch(areas_mm2: Float[ArrayLike, "m n"], lengths_mm: Float[ArrayLike, "m n"]) -> Formants:
    """:func:`formants` of ``m`` tracts at once (all losses on), compiled once per shape."""
    return jax.vmap(formants)(areas_mm2, lengths_mm)


def uniform_tube(length_mm: float, area_mm2: float = 300.0, n: int = 40) -> tuple[Array, Array]:
    """A uniform tube of ``length_mm`` as ``(areas, lengths)`` of ``n`` sections."""
    return jnp.full(n, float(area_mm2)), jnp.full(n, float(length_mm) / n)
