"""A frozen study's bundle in tests: a private copy of a study to damage, where its bundle
lies, and its working bank changed and frozen again."""

import json
import shutil
from pathlib import Path

from tests.conftest import SmallStudy, freeze_bundle_of


def copied(study: SmallStudy, tmp_path) -> SmallStudy:
    """A copy of the small study's data dir (models and data linked) and configs."""
    data, configs = tmp_path / "var", tmp_path / "configs"
    data.mkdir()
    for sub in ("data", "models"):
        (data / sub).symlink_to(study.data_dir / sub)
    for sub in ("trials", "bundles"):
        shutil.copytree(study.data_dir / sub, data / sub)
    shutil.copytree(study.configs_dir, configs)
    return SmallStudy(data, configs, study.study_id)


def bundle_root(study: SmallStudy) -> Path:
    """The folder of the study's frozen bundle."""
    return study.layout.bundle_dir(study.study_id)


def refrozen_with(study: SmallStudy, change) -> None:
    """Change the working bank's JSON with `change` and freeze the bundle again."""
    path = study.layout.bank(study.study_id)
    raw = json.loads(path.read_text())
    change(raw)
    path.write_text(json.dumps(raw))
    freeze_bundle_of(study)


def refrozen_each_trial(study: SmallStudy, change) -> None:
    """Change every trial of the working bank with `change` and freeze the bundle again."""
    def change_each(raw: dict) -> None:
        for world in raw["worlds"].values():
            for trial in world["trials"]:
                change(trial)

    refrozen_with(study, change_each)
