"""Where every generated file lives under the data dir: the one place that spells those paths.

    <data dir>/                                   var/ unless TOMSTUDY_DATA_DIR moves it
      data/<world>/trajectories.npz, meta.json, trajectories.png        simulate
      policies/<policy>.zip, <policy>.meta.json                         simulate --policy sac
      models/<world>/<model>/seed<k>/checkpoint.pt, metrics.json, loss.png   train
      models/<world>/<model>/seed<k>/fields/                            fields
      models/selection/<world>/, models/sweep/<world>/                  select, sweep
      models/interaction/<scenario>/                                    interaction
      trials/<study>/bank.json, meta.json                               build-trials
      trials/<study>/display_check.json                                 check-display
      bundles/<study>/manifest.json, bank.json.gz, models/, configs/    bundle build
      reports/<study>/, power-<study>-<bots>/, instrument-<study>/      analyze, power, instrument
      reports/prereg-<study>/                                           prereg
      reports/interaction/<scenario>/                                   interaction
      study.db, pilot_<bots>.db                                         serve, make pilot
      studies/<study>/completion_codes.json     a study's generated codes   serve, codes
      archives/registry.json  every archive written: its path, hash and participants   archive
      recordings/             a lab's recordings (TOMSTUDY_RECORDINGS_DIR)   import-recordings

A study's model family (its config's `models.seeds`) lives at `checkpoint(world, model, seed)`;
the bundle a study is served from is frozen from those files (app/bank/bundle.py).
"""

from dataclasses import dataclass
from pathlib import Path

DEFAULT_DATA_DIR = Path(__file__).resolve().parent.parent / "var"
CHECKPOINT_FILE = "checkpoint.pt"


@dataclass(frozen=True)
class Layout:
    """The generated paths under one data dir."""

    root: Path
    recordings_root: Path | None = None  # default: <root>/recordings

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    def resolve(self, path: Path | str) -> Path:
        """A path a config gives relative to the data dir (an absolute one stays as it is)."""
        return self.root / path

    # -- simulate
    def world_data(self, world: str) -> Path:
        """data/<world>/: one world's simulated trajectories and what describes them."""
        return self.root / "data" / world

    def trajectories(self, world: str) -> Path:
        """data/<world>/trajectories.npz."""
        return self.world_data(world) / "trajectories.npz"

    def trajectories_meta(self, world: str) -> Path:
        """data/<world>/meta.json (config, seed, hashes, wall time of the simulation)."""
        return self.world_data(world) / "meta.json"

    def trajectories_plot(self, world: str) -> Path:
        """data/<world>/trajectories.png."""
        return self.world_data(world) / "trajectories.png"

    def policy(self, name: str) -> Path:
        """policies/<name>.zip: a trained world policy (SAC for Obstacle)."""
        return self.root / "policies" / f"{name}.zip"

    def policy_meta(self, name: str) -> Path:
        """policies/<name>.meta.json: the config the policy was trained on."""
        return self.root / "policies" / f"{name}.meta.json"

    # -- train
    def model_dir(self, world: str, model_name: str, seed: int = 0) -> Path:
        """models/<world>/<model>/seed<k>/: checkpoint.pt, metrics.json, loss.png, fields/."""
        return self.root / "models" / world / model_name / f"seed{seed}"

    def checkpoint(self, world: str, model_name: str, seed: int = 0) -> Path:
        """models/<world>/<model>/seed<k>/checkpoint.pt."""
        return self.model_dir(world, model_name, seed) / CHECKPOINT_FILE

    def selection_dir(self, world: str) -> Path:
        """models/selection/<world>/: `tomstudy select` outputs."""
        return self.root / "models" / "selection" / world

    def sweep_dir(self, world: str) -> Path:
        """models/sweep/<world>/: `tomstudy sweep` settings and sweep.jsonl."""
        return self.root / "models" / "sweep" / world

    def interaction_models(self, scenario: str) -> Path:
        """models/interaction/<scenario>/: every seed's Ours and VAE on INTERACTION."""
        return self.root / "models" / "interaction" / scenario

    # -- build-trials
    def bank_dir(self, study_id: str) -> Path:
        """trials/<study>/: bank.json and its meta.json."""
        return self.root / "trials" / study_id

    def bank(self, study_id: str) -> Path:
        """trials/<study>/bank.json."""
        return self.bank_dir(study_id) / "bank.json"

    def bank_meta(self, study_id: str) -> Path:
        """trials/<study>/meta.json (input hashes of the bank)."""
        return self.bank_dir(study_id) / "meta.json"

    def display_check(self, study_id: str) -> Path:
        """trials/<study>/display_check.json: `tomstudy check-display`."""
        return self.bank_dir(study_id) / "display_check.json"

    # -- bundle build
    def bundle_dir(self, study_id: str) -> Path:
        """bundles/<study>/: the frozen bundle `tomstudy bundle build` makes."""
        return self.root / "bundles" / study_id

    # -- reports
    def report_dir(self, study_id: str) -> Path:
        """reports/<study>/: `tomstudy analyze`."""
        return self.root / "reports" / study_id

    def power_report(self, study_id: str, bots: str) -> Path:
        """reports/power-<study>-<bots>/: `tomstudy power`."""
        return self.root / "reports" / f"power-{study_id}-{bots}"

    def instrument_report(self, study_id: str) -> Path:
        """reports/instrument-<study>/: `tomstudy instrument`."""
        return self.root / "reports" / f"instrument-{study_id}"

    def prereg_report(self, study_id: str) -> Path:
        """reports/prereg-<study>/: `tomstudy prereg`."""
        return self.root / "reports" / f"prereg-{study_id}"

    def interaction_report(self, scenario: str) -> Path:
        """reports/interaction/<scenario>/: `tomstudy interaction`."""
        return self.root / "reports" / "interaction" / scenario

    # -- recorded worlds
    def recordings(self) -> Path:
        """recordings/: where a lab keeps its recordings (a licensed download, its own logs);
        a recorded world's config names its files relative to it. Never in git."""
        return Path(self.recordings_root) if self.recordings_root else self.root / "recordings"

    # -- databases
    def completion_codes(self, study_id: str) -> Path:
        """studies/<study>/completion_codes.json: the study's generated completion codes."""
        return self.root / "studies" / study_id / "completion_codes.json"

    def archive_registry(self) -> Path:
        """archives/registry.json: the archives `tomstudy archive` wrote (path, SHA-256,
        participant ids, time), so a withdrawal names the ones that hold the person."""
        return self.root / "archives" / "registry.json"

    def study_database(self) -> Path:
        """study.db: the SQLite database `serve` uses when DATABASE_URL is unset."""
        return self.root / "study.db"

    def pilot_database(self, bots: str) -> Path:
        """pilot_<bots>.db: the database `make pilot` runs bots of one preset against."""
        return self.root / f"pilot_{bots}.db"
