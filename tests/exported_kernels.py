"""A kernel for tests/test_exported.py, importable by the fresh processes the tests start:
mixed array and static arguments (an equinox Module with a static field, a Python number,
None), outputs with a static leaf, and a LAPACK call (a custom call JAX does not promise
to keep stable). ``TRACES`` grows by one each time its Python runs (a trace).

    python tests/exported_kernels.py OUT.npz   # call it once, save outputs and counts
                                               # (traces, kernel.traces, loads, executables)
"""

from __future__ import annotations

import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from cassi_fit._exported import exported

TRACES: list[int] = []


class Pair(eqx.Module):
    a: jax.Array
    b: jax.Array
    label: str = eqx.field(static=True)


@exported
def kernel(pair, power, offset=None):
    TRACES.append(power)
    q, r = jnp.linalg.qr(pair.a)
    shifted = pair.b if offset is None else pair.b + offset
    out = Pair(q @ r ** power, jnp.cumsum(jnp.sin(shifted)), pair.label + "!")
    return out, {"power": power, "trace": jnp.trace(r)}, None


def inputs(n: int = 4):
    """Fixed arguments: ``(pair, power, offset)``."""
    rng = np.random.default_rng(7)
    return (Pair(jnp.asarray(rng.normal(size=(n, n))), jnp.asarray(rng.normal(size=n)),
                 "pair"), 3, jnp.asarray(0.25))


def flat_outputs(out) -> dict[str, np.ndarray]:
    pair, extra, nothing = out
    assert pair.label == "pair!" and extra["power"] == 3 and nothing is None
    return {"a": np.asarray(pair.a), "b": np.asarray(pair.b), "trace": np.asarray(extra["trace"])}


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    out = flat_outputs(kernel(*inputs()))
    executables = sum(isinstance(e.call, jax.stages.Compiled) for e in kernel._entries.values())
    np.savez(sys.argv[1], **out,
             counts=np.array([len(TRACES), kernel.traces, kernel.loads, executables]),
             scipy_linalg=np.array("scipy.linalg" in sys.modules))
