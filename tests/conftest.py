"""Shared test set-up: float64 on (precision is asserted), and the synthetic subject zoo."""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
