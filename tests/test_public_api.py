"""Every name the package advertises resolves, and importing the package starts no JAX."""

import subprocess
import sys

import cassi_fit


def test_every_public_name_resolves():
    for name in cassi_fit.__all__:
        assert getattr(cassi_fit, name) is not None, name


def test_import_is_cheap():
    code = "import sys, cassi_fit; print('jax' in sys.modules, 'OpenGL' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
