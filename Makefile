# Two commands do all set-up on a fresh machine (Python 3.11 only):
#   make demo   -- build the venv if needed, then run `cassi demo` on the synthetic corpus
#   make test   -- build the venv if needed, then run the whole test suite (two pytest-xdist
#                  workers, one test file each at a time, each on its share of the cores)
#   make lint   -- ruff, the import-linter contracts and the public annotations check
#   make browser -- Debian's chromium for the viewer's browser tests (make test runs it first)
#   make notebooks -- run the notebooks and store them with their outputs
#   make docs   -- the API reference from the docstrings, into build/docs_site/ (index.html)
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# The real XRMB recording for the real referee (read-only; never copied into the project):
# beside the checkout (../shared); `make experiments XRMB_JW11=DIR` names another.
XRMB_JW11 ?= $(wildcard ../shared/data/xrmb_jw11)

.PHONY: demo test venv pictures bench experiments lint docs clean browser notebooks

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,corpus,docs]'
	$(BIN)/python -m ipykernel install --prefix $(VENV) --name python3 >/dev/null
	@touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/cassi demo --out demo_output

# The viewer's browser tests (tests/test_viewer.py) drive Debian's chromium through Playwright
# for Python (a test extra; no browser is downloaded). Installed here when missing (apt-get,
# as root); where it cannot be, those tests skip with one line saying why.
browser:
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || \
	  { (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) \
	      >/dev/null 2>&1 && echo "browser: installed Debian's chromium" || \
	    echo "browser: chromium could not be installed here; the viewer's browser tests will skip"; }

test: $(STAMP) browser
	$(BIN)/python -m pytest -q -p no:cacheprovider -n 2 --dist loadfile

pictures: $(STAMP) browser
	$(BIN)/python model/render_pictures.py --out model/pictures
	$(BIN)/python model/render_face.py --out model/pictures
	$(BIN)/python experiments/viewer_screenshot.py --out docs/images/viewer.png

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_jaw.py
	$(BIN)/python benchmarks/bench_render.py --docs docs/generated
	$(BIN)/python benchmarks/bench_animation.py --docs docs/generated
	$(BIN)/python benchmarks/bench_startup.py --docs docs/generated
	$(BIN)/python benchmarks/bench_trace.py --docs docs/generated
	$(BIN)/python benchmarks/bench_corpus.py --write docs/generated/bench_corpus.md
	$(BIN)/python benchmarks/bench_realtime.py --docs docs/generated
	$(BIN)/python experiments/quote_tables.py

experiments: $(STAMP)
	$(BIN)/python experiments/jaw_comparison.py --out experiments/output --docs docs/generated --force
	$(BIN)/python experiments/single_sensor_jaw.py --out experiments/output --docs docs/generated --force
	$(BIN)/python experiments/synthetic_realism.py --out experiments/output --docs docs/generated --force
	$(BIN)/python experiments/subject_fitting.py --out experiments/output --docs docs/generated --force
	$(BIN)/python experiments/calibration_limits.py --out experiments/output --docs docs/generated --force
	$(BIN)/python experiments/cassi_mode.py --subjects 5 --tasks tp011 tp040 --stride 1
	$(BIN)/python experiments/tongue_volume.py --subjects 2 --stride 1
	@if [ -d "$(XRMB_JW11)" ]; then \
	  $(BIN)/python experiments/real_referee.py $(XRMB_JW11) --out experiments/output \
	    --docs docs/generated --force; \
	else echo "real_referee: skipped, no real recording (make experiments XRMB_JW11=DIR)"; fi
	$(BIN)/python experiments/acoustic_referee.py $(if $(XRMB_JW11),--jw11 $(XRMB_JW11),) --docs docs/generated --force
	$(BIN)/python experiments/acoustic_tract_diagnosis.py $(if $(XRMB_JW11),--jw11 $(XRMB_JW11),) --docs docs/generated --force
	$(BIN)/python experiments/mistrack_detection.py --docs docs/generated --force
	$(BIN)/python experiments/placement.py --docs docs/generated --xrmb $(XRMB_JW11)
	$(BIN)/python experiments/channel_identification.py --docs docs/generated
	$(BIN)/python experiments/quote_tables.py

# The notebooks stored with their outputs (figures, tables, the inline viewer), so that a code
# host's web page shows them; tests/test_notebooks_stored.py checks they are current.
notebooks: $(STAMP)
	$(BIN)/python notebooks/store_outputs.py

# ruff; the import-linter contracts (layers, no cycles; pyproject.toml); the public surface's
# type annotations (tests/test_architecture.py, which also runs the contracts).
lint: $(STAMP)
	$(BIN)/ruff check cassi_fit tests experiments benchmarks model
	$(BIN)/lint-imports --no-cache
	$(BIN)/python -m pytest -q -p no:cacheprovider tests/test_architecture.py

# The API reference (mkdocs.yml): every public name's docstring, built with --strict so that a
# warning fails (tests/test_docs_api.py builds it the same way).
docs: $(STAMP)
	$(BIN)/mkdocs build --strict

clean:
	rm -rf $(VENV) demo_output
