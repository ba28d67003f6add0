"""A study's frozen bundle: the one thing a server serves and a preregistration can name.

    <bundle>/manifest.json                         format, SHA-256 and size of every other file,
                                                   the bank's hash, every checkpoint's and
                                                   coarse observer's content hash, the
                                                   checkpoints that hit their training cap
                                                   unconverged, and where and how it was built
    <bundle>/bank.json.gz                          the trial bank (app/study/trials.py)
    <bundle>/bank_meta.json                        how the bank was built (its meta.json)
    <bundle>/models/<world>/<model>/seed<k>.pt.gz  every checkpoint whose answers the bank stores
    <bundle>/models/<world>/<model>/seed<k>.metrics.json.gz   its training and test figures
    <bundle>/data/<world>.meta.json                how the trajectories were simulated (hashes)
    <bundle>/selection/<world>.json                how the build chose a world's model sizes,
                                                   when training.yaml chose none (a new world)
    <bundle>/configs/...                           the study, training, selection, observer and
                                                   world configs that made it

The coarse observers (app/observers/predictor.py) answer under the bundle's own observers
config. A plug-in predictor (app/predictors/) is code, not a file of the bundle: the manifest's
`predictors` records each one's name, content hash and the distribution and version that
provided it, and the server recomputes its answers from the installed plug-in at start-up.

A study config's `bundle` says where its bundle is: `shipped` (<configs dir>/bundles/<study>/,
in git, so every machine serves the same study) or `built` (<data dir>/bundles/<study>/, made
by `tomstudy bundle build`). freeze.py writes a bundle; verify.py opens one, refusing a
missing, altered or unlisted file and a live config that shapes the bank otherwise.
"""

from dataclasses import dataclass, field
from pathlib import Path

from app.configio import load_yaml_model
from app.core.contracts import COARSE_OBSERVERS
from app.layout import Layout
from app.observers.config import OBSERVERS_FILE, load_observers
from app.observers.predictor import ObserverPredictor
from app.predictors.builtin import CheckpointPredictor
from app.predictors.registry import load_predictor
from app.study.config import StudyConfig
from app.study.trials import TrialBank

FORMAT = "tomstudy-bundle-v1"
MANIFEST = "manifest.json"
BANK = "bank.json.gz"
BANK_META = "bank_meta.json"
MODELS = ("ours", "vae")
SHARED_CONFIGS = ("training.yaml", "model_selection.yaml", OBSERVERS_FILE)
BUNDLES = "bundles"  # the folder of shipped bundles in the configs dir


class BundleError(RuntimeError):
    """A bundle is missing, altered, or does not belong to the study config that names it."""


def checkpoint_file(world: str, model: str, seed: int) -> str:
    """A checkpoint's path inside a bundle."""
    return f"models/{world}/{model}/seed{seed}.pt.gz"


def metrics_file(world: str, model: str, seed: int) -> str:
    """A checkpoint's metrics.json (training history, test figures) inside a bundle."""
    return f"models/{world}/{model}/seed{seed}.metrics.json.gz"


def shipped_dir(configs_dir: Path, study_id: str) -> Path:
    """<configs dir>/bundles/<study>/: where a study's bundle ships with the code."""
    return Path(configs_dir) / BUNDLES / study_id


def bundle_dir(config: StudyConfig, study_id: str, configs_dir: Path, layout: Layout) -> Path:
    """Where the study's config says its bundle is (shipped or built)."""
    if config.bundle == "shipped":
        return shipped_dir(configs_dir, study_id)
    return layout.bundle_dir(study_id)


@dataclass
class Bundle:
    """An opened, verified bundle: its manifest, its bank and its checkpoints (loaded lazily)."""

    root: Path
    manifest: dict
    bank: TrialBank
    _models: dict = field(default_factory=dict, repr=False)
    _plugins: dict = field(default_factory=dict, repr=False)

    @property
    def study_id(self) -> str:
        """The study the bundle was built for."""
        return self.manifest["study_id"]

    @property
    def seeds(self) -> list[int]:
        """The model family's seeds, the primary first."""
        return list(self.manifest["seeds"])

    def study_config(self) -> StudyConfig:
        """The study config the bundle was built from (its configs/<study>.yaml)."""
        return load_yaml_model(self.root / "configs" / f"{self.study_id}.yaml", StudyConfig)

    @property
    def plugins(self) -> dict[str, dict]:
        """The manifest's plug-in predictors: name -> content hash, distribution, version."""
        return dict(self.manifest.get("predictors", {}))

    def predictor(self, world: str, name: str, seed: int):
        """The predictor whose answers the bank stores as `name`: a checkpoint of the bundle
        (Ours, the VAE), a coarse observer under the bundle's observers config, or an installed
        plug-in (UnknownPredictor when it is not installed)."""
        if name in MODELS:
            return CheckpointPredictor(self.model(world, name, seed))
        if name not in self._plugins:  # code: the same for every world
            self._plugins[name] = (
                ObserverPredictor(name, load_observers(self.root / "configs" / OBSERVERS_FILE))
                if name in COARSE_OBSERVERS else load_predictor(name))
        return self._plugins[name]

    def model(self, world: str, model: str, seed: int):
        """One checkpoint of the bundle as a TrainedModel (loaded once)."""
        from app.learning.checkpoint import load_model

        key = (world, model, seed)
        if key not in self._models:
            self._models[key] = load_model(self.root / checkpoint_file(*key), world=world)
        return self._models[key]
