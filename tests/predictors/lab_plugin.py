"""A lab's own plug-in predictor as a real installed distribution: a package and its
dist-info with an entry point in group `tomstudy.predictors`, on a folder put on sys.path."""

from pathlib import Path

PACKAGE = '''
import numpy as np

from app.predictors.protocol import PredictorAnswer, code_hash


class StandStill:
    """Predicts a slow drift along each start's heading (a lab's toy predictor)."""

    name = "{name}"
    speed_mps = 0.25

    @property
    def content_hash(self):
        return code_hash(self.name, "1", {{"speed_mps": self.speed_mps}})

    def answer(self, history, starts, headings, dt_s, n_steps):
        step = self.speed_mps * np.stack([np.cos(headings), np.sin(headings)], axis=-1)
        return PredictorAnswer(np.repeat(step[:, None, :], n_steps, axis=1))
'''


def install_lab_plugin(folder: Path, name: str = "drift", dist: str = "lab_predictors",
                       factory: str = "StandStill") -> Path:
    """Write the package `<dist>` and its dist-info registering `name` under `folder`; returns
    the folder to put on sys.path."""
    package = folder / dist
    package.mkdir(parents=True)
    (package / "__init__.py").write_text(PACKAGE.format(name=name))
    info = folder / f"{dist}-0.3.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.3.1\n")
    (info / "entry_points.txt").write_text(
        f"[tomstudy.predictors]\n{name} = {dist}:{factory}\n")
    return folder
