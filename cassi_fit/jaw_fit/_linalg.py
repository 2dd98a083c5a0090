"""Symmetric block-tridiagonal linear algebra with 2x2 blocks (the smooth pivot's normal
equations): solve, selected inversion, quadratic form. O(m) time and memory, never a dense
matrix. A matrix is ``(diag (m, 2, 2), upper (m - 1, 2, 2))``: ``N_jj`` and ``N_j,j+1``
(``N_j+1,j`` is the transpose).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float


def block_tridiagonal_solve(diag: Float[Array, "m 2 2"], upper: Float[Array, "m-1 2 2"],
                            rhs: Float[Array, "m 2"]) -> Float[Array, "m 2"]:
    """Solve ``N x = rhs`` for a symmetric block-tridiagonal ``N`` with 2x2 blocks.

    diag (m, 2, 2) = ``N_jj``, upper (m - 1, 2, 2) = ``N_j,j+1`` (``N_j+1,j`` is its
    transpose), rhs (m, 2). Block Thomas algorithm (block LDL^T; stable for positive
    definite ``N``): O(m) time and memory in one forward and one backward ``lax.scan``.
    """
    zero = jnp.zeros_like(diag[0])
    upper_pad = jnp.concatenate([upper, zero[None]])
    lower_prev = jnp.concatenate([zero[None], upper])  # N_j,j-1 = upper[j-1]^T

    def forward(carry, blocks):
        c_prev, d_prev = carry
        dj, uj, lj, bj = blocks
        lt = lj.T
        pivot = dj - lt @ c_prev
        c = jnp.linalg.solve(pivot, uj)
        d = jnp.linalg.solve(pivot, bj - lt @ d_prev)
        return (c, d), (c, d)

    _, (c, d) = jax.lax.scan(forward, (zero, jnp.zeros_like(rhs[0])),
                             (diag, upper_pad, lower_prev, rhs))

    def backward(x_next, blocks):
        cj, dj = blocks
        x = dj - cj @ x_next
        return x, x

    _, x = jax.lax.scan(backward, jnp.zeros_like(rhs[0]), (c, d), reverse=True)
    return x


def block_tridiagonal_inverse_blocks(
    diag: Float[Array, "m 2 2"], upper: Float[Array, "m-1 2 2"]
) -> tuple[Float[Array, "m 2 2"], Float[Array, "m-1 2 2"]]:
    """The blocks ``(C_jj, C_j,j+1)`` of ``C = N^-1`` for the symmetric positive definite
    block-tridiagonal ``N`` of :func:`block_tridiagonal_solve` (selected inversion).

    Forward: Schur complements ``S_0 = N_00``, ``S_j = N_jj - U_j-1^T S_j-1^-1 U_j-1``.
    Backward (as in a Rauch-Tung-Striebel smoother): ``C_m-1 = S_m-1^-1``,
    ``G_j = S_j^-1 U_j``, ``C_jj = S_j^-1 + G_j C_j+1,j+1 G_j^T``,
    ``C_j,j+1 = -G_j C_j+1,j+1``. O(m) time and memory; the dense inverse is never formed.
    """
    zero = jnp.zeros_like(diag[0])
    lower_prev = jnp.concatenate([zero[None], upper])

    def forward(s_inv_prev, blocks):
        dj, uprev = blocks
        s_inv = jnp.linalg.inv(dj - uprev.T @ s_inv_prev @ uprev)
        return s_inv, s_inv

    _, s_inv = jax.lax.scan(forward, zero, (diag, lower_prev))

    def backward(c_next, blocks):
        s_inv_j, uj = blocks
        g = s_inv_j @ uj
        c = s_inv_j + g @ c_next @ g.T
        return c, (c, -g @ c_next)

    last = s_inv[-1]
    _, (head, up) = jax.lax.scan(backward, last, (s_inv[:-1], upper), reverse=True)
    return jnp.concatenate([head, last[None]]), up


def block_quadratic(diag: Float[Array, "m 2 2"], upper: Float[Array, "m-1 2 2"],
                    x: Float[Array, "m 2"]) -> Float[Array, ""]:
    """``x^T N x`` for the block-tridiagonal ``N`` of :func:`block_tridiagonal_solve`."""
    return (jnp.einsum("ji,jik,jk->", x, diag, x)
            + 2.0 * jnp.einsum("ji,jik,jk->", x[:-1], upper, x[1:]))
