# Two entry points for a fresh machine: `make serve` and `make test`.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# Every dependency is pinned in requirements/dev.txt (runtime.txt: what the image and
# `make serve` install); `make lock` re-resolves both from pyproject.toml.
LOCK := requirements/dev.txt
RUNTIME_LOCK := requirements/runtime.txt
RUNTIME_STAMP := $(VENV)/.installed-runtime
# uv installs the pinned set in seconds where pip takes minutes (a fresh clone's first
# `make serve` waits for it); torch goes first through pip, which reads this machine's
# wheel sources (an unpinned resolve pulls gigabytes of CUDA wheels), and uv keeps it.
# --compile-bytecode: uv writes no .pyc by default, and where PYTHONDONTWRITEBYTECODE is set
# (CI, the image) every process then compiled pandas, fastapi, sqlalchemy... again at each
# start: `import app.main` took 3.55 s instead of 2.05 s, in every server and CLI run
UV := $(BIN)/uv pip install -q --compile-bytecode --python $(BIN)/python

.PHONY: install serve test lint docs data bench pilot screens screens-recorded fuzz lock clean

$(RUNTIME_STAMP): pyproject.toml $(RUNTIME_LOCK)
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q pip==26.3 uv==0.13.9
	$(BIN)/pip install -q -c $(RUNTIME_LOCK) torch==2.13.0
	$(UV) -c $(RUNTIME_LOCK) -e .
	touch $(RUNTIME_STAMP)

$(STAMP): $(RUNTIME_STAMP) $(LOCK)
	$(UV) -c $(LOCK) -e '.[dev]'
	touch $(STAMP)

# axe-core for the browser tests' accessibility checks (tests/e2e/axe.py), pinned by the lock
AXE := tests/e2e/node_modules/axe-core/axe.min.js
$(AXE): tests/e2e/package.json tests/e2e/package-lock.json
	npm ci --prefix tests/e2e --no-audit --no-fund --loglevel=error
	touch $(AXE)

install: $(STAMP) $(AXE)

data: $(STAMP)
	$(BIN)/tomstudy simulate highway --n 2000 --seed 0 --if-missing
	$(BIN)/tomstudy simulate obstacle --n 2000 --seed 0 --if-missing

# serve the paper's study at http://127.0.0.1:8000/s/paper_study from its shipped bundle
# (nothing to simulate or train); a `bundle: built` study is built first where missing
serve: $(RUNTIME_STAMP)
	$(BIN)/tomstudy serve --prepare --study paper_study $(SERVE_ARGS)

# the documentation site (mkdocs.yml, docs/) into site/; --strict: a broken link, anchor or nav
# entry fails, so `make test` (which builds it first) catches it
MKDOCS := NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet
docs: $(STAMP)
	$(MKDOCS)

# the suite on TEST_WORKERS processes (pytest-xdist, one file per process at a time, so a
# file's session fixtures stay in one process), then the `serial` tests xdist cannot run;
# compileall first: the suite starts dozens of servers and CLI runs, and under
# PYTHONDONTWRITEBYTECODE each would compile the project's modules again
TEST_WORKERS ?= 2
test: $(STAMP) $(AXE)
	$(BIN)/ruff check app analysis tests tools benchmarks
	$(MKDOCS)
	$(BIN)/python -m compileall -q app analysis tests tools benchmarks
	$(BIN)/pytest -q -n $(TEST_WORKERS) --dist loadfile -m "not serial" --durations=15
	$(BIN)/pytest -q -m serial

# Pilot end to end on a fresh database: serve STUDY, KIND bots (coarse|coarse_scene|
# coarse_momentum|coarse_relative|precise|random), analyze. The database is app/layout.py's pilot_database(KIND) under the default data
# dir (STUDY other than paper_study: pilot_<STUDY>_<KIND>). Bots answer without thinking from
# one address, so this loopback server has no rate limits.
KIND ?= coarse
STUDY ?= paper_study
PILOT_NAME = $(if $(filter paper_study,$(STUDY)),$(KIND),$(STUDY)_$(KIND))
PILOT_PORT ?= 8765
# random clickers fail the attention checks by design (as they should); their report waives
# that rule so the random baseline can be read
PILOT_WAIVE = $(if $(filter random,$(KIND)),--waive failed_attention_check)
pilot: $(STAMP)
	rm -f var/pilot_$(PILOT_NAME).db*
	DATABASE_URL=sqlite:///$(CURDIR)/var/pilot_$(PILOT_NAME).db TOMSTUDY_TRUST_CLIENT_CLOCK=1 \
	  TOMSTUDY_RATE_LIMIT_STARTS= TOMSTUDY_RATE_LIMIT_REQUESTS= \
	  $(BIN)/tomstudy serve --prepare \
	  --study $(STUDY) --port $(PILOT_PORT) & pid=$$!; \
	for i in $$(seq 3600); do curl -sf http://127.0.0.1:$(PILOT_PORT)/s/$(STUDY) >/dev/null && break; sleep 1; done; \
	$(BIN)/tomstudy pilot --url http://127.0.0.1:$(PILOT_PORT) --study $(STUDY) --n 22 --kind $(KIND) --concurrency 8; \
	status=$$?; kill $$pid; wait $$pid; test $$status -eq 0
	$(BIN)/tomstudy analyze --study $(STUDY) --database-url sqlite:///$(CURDIR)/var/pilot_$(PILOT_NAME).db \
	  --out var/reports/pilot_$(PILOT_NAME) $(PILOT_WAIVE)

# The researcher dashboard and one replay on a copy of the coarse pilot's database (var/screens)
screens: $(STAMP)
	$(BIN)/python -m tests.e2e.shoot_dashboard

# The recorded worlds (generated recordings) as a participant and a researcher see them (var/screens)
screens-recorded: $(STAMP)
	$(BIN)/python -m tests.e2e.shoot_recorded

# Schemathesis with every check on the study API: at least 5,000 cases, 0 failures (issue 10)
fuzz: $(STAMP)
	SCHEMATHESIS_MAX_EXAMPLES=600 SCHEMATHESIS_MIN_CASES=5000 \
	  $(BIN)/pytest tests/http/test_schemathesis.py -q -s -p no:cacheprovider

bench: $(STAMP)
	for f in benchmarks/[!_]*.py; do $(BIN)/python $$f || exit 1; done

# Re-resolve every pinned dependency from pyproject.toml (then run `make test` on the result).
# pip-compile runs from a throwaway venv; torch's local "+cpu" label is dropped so the pins
# install from PyPI too.
lock:
	$(PYTHON) -m venv $(VENV)-lock && $(VENV)-lock/bin/pip install -q pip-tools==7.6.2
	$(VENV)-lock/bin/pip-compile -q --strip-extras --allow-unsafe --no-emit-index-url \
	  --no-emit-find-links -o requirements/runtime.txt pyproject.toml
	$(VENV)-lock/bin/pip-compile -q --strip-extras --allow-unsafe --no-emit-index-url \
	  --no-emit-find-links --extra dev -o requirements/dev.txt pyproject.toml
	sed -i 's/^torch==\(.*\)+cpu$$/torch==\1/' requirements/runtime.txt requirements/dev.txt
	rm -rf $(VENV)-lock

clean:
	rm -rf var site .pytest_cache .ruff_cache
