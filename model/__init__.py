"""The toolkit's face model data (format: ``model/README.md``), built by ``build_model.py``.

This folder is installed as the package data of ``cassi_fit.model`` (pyproject.toml maps
it with ``package-dir``), so ``cassi_fit.face_model.load_model()`` finds the files through
``importlib.resources`` in a wheel, a ``pip install .`` and an editable install alike.
"""
