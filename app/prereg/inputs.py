"""What a preregistration is written from, in this order of authority: the study config, its
frozen bundle (app/bank/served.py finds and verifies it), the instrument's result and the power
simulation's; each read once as a Source (app/prereg/sources.py)."""

from dataclasses import dataclass, field
from pathlib import Path

import analysis.stats
import app.core.contracts
from app.bank.bundle import BANK_META, MANIFEST
from app.bank.served import served_bundle
from app.observers.config import OBSERVERS_FILE
from app.observers.family import COARSE_VARIANTS
from app.prereg.sources import (
    REPO_ROOT,
    Ledger,
    Source,
    dig,
    module_source,
    parse,
    read_source,
    shown_path,
)
from app.settings import Settings
from app.study.config import StudyConfig, load_study_config, study_config_path

# the table of departures from the paper, kept once in the docs and shown as it is
DEPARTURES = REPO_ROOT / "docs" / "reproduce" / "departures.md"


@dataclass(frozen=True)
class RunResult:
    """One command's result file: usable (on the bundle's bank), or why not and what makes it."""

    name: str
    command: str
    source: Source | None
    problem: str = ""

    @property
    def usable(self) -> bool:
        """Present and run on the bundle's bank."""
        return self.source is not None and not self.problem


@dataclass
class Inputs:
    """Every file the preregistration of one study reads, and the ledger of what it took."""

    study_id: str
    config: StudyConfig
    study_config: Source  # the live config file; its data is the typed, validated config
    raw_config: dict  # the same file's keys as written (to tell a set key from a default)
    bundle_root: Path
    manifest: Source
    bank_meta: Source
    observers: Source  # the bundle's frozen observers config
    worlds: dict[str, Source]  # the bundle's frozen world configs
    instrument: RunResult
    goal: RunResult
    power: dict[str, RunResult]
    stats: Source  # analysis/stats.py: ALPHA
    contracts: Source  # app/core/contracts.py: the default SESOI, the export columns
    departures: Source | None
    ledger: Ledger = field(default_factory=Ledger)

    def setting(self, key: str, what: str):
        """A study config value by key path, cited (a key the file leaves out is its default)."""
        try:
            dig(self.raw_config, key)
            note = ""
        except (KeyError, IndexError, ValueError, AttributeError, TypeError):
            note = " (not set: the default)"
        return self.ledger.take(self.study_config, key, what, note)

    def results(self) -> list[RunResult]:
        """The instrument's and the power simulation's result files."""
        return [self.instrument, self.goal, *self.power.values()]


def gather(settings: Settings, study_id: str) -> Inputs:
    """Read every input of `study_id`'s preregistration (ConfigError for an unknown study,
    BundleError for a missing or altered bundle)."""
    config = load_study_config(settings, study_id)
    bundle = served_bundle(settings, study_id)
    config_path = study_config_path(settings, study_id)
    bank = bundle.manifest["bank_sha256"]
    layout = settings.layout
    reports = layout.instrument_report(study_id)
    instrument_cmd = f"tomstudy instrument --study {study_id}"
    return Inputs(
        study_id=study_id, config=config,
        study_config=read_source(config_path, data=config),
        raw_config=parse(config_path),
        bundle_root=bundle.root,
        manifest=read_source(bundle.root / MANIFEST),
        bank_meta=read_source(bundle.root / BANK_META),
        observers=read_source(bundle.root / "configs" / OBSERVERS_FILE),
        worlds={w: read_source(bundle.root / "configs" / "worlds" / f"{w}.yaml")
                for w in config.worlds},
        instrument=run_result("instrument", reports / "instrument.json", bank, instrument_cmd),
        goal=run_result("design goal", reports / "goal.json", bank, instrument_cmd),
        power={kind: run_result(f"power ({kind})", layout.power_report(study_id, kind)
                                / "power.json", bank,
                                f"tomstudy power --study {study_id} --kind {kind}")
               for kind in COARSE_VARIANTS},
        stats=module_source(analysis.stats), contracts=module_source(app.core.contracts),
        departures=read_source(DEPARTURES) if DEPARTURES.is_file() else None)


def run_result(name: str, path: Path, bank_sha256: str, command: str) -> RunResult:
    """A command's result file, with the problem that makes it unusable ('' if none): missing,
    or run on a bank other than the bundle's."""
    if not path.is_file():
        return RunResult(name, command, None,
                         f"{shown_path(path)} not found: `{command}` has not run")
    source = read_source(path)
    ran_on = source.data.get("bank_sha256") or ""
    if ran_on != bank_sha256:
        on = f"bank {ran_on[:12]}" if ran_on else "a bank it does not record"
        return RunResult(name, command, source,
                         f"{source.shown_path} ran on {on}, not the bundle's {bank_sha256[:12]}: "
                         f"rerun `{command}`")
    return RunResult(name, command, source)
