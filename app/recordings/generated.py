"""GENERATED, NOT REAL DATA: the interaction study's two scenarios as INTERACTION-format files.

For demos, tests and labs that have not downloaded the dataset yet: app/interaction/
synthetic.py's generated traffic, a roundabout in the v1.2 layout and an intersection in the
v1.0 layout, each with its lanelet2-style map, where study_configs/worlds/roundabout.yaml and
intersection.yaml look for the real download. Nothing here is a recording.
"""

from pathlib import Path

from app.interaction.synthetic import generate

# scenario, devkit layout, seed: one of each layout, so a study exercises both readers
STUDY_SCENARIOS = (("DR_USA_Roundabout_FT", "v1.2", 0), ("DR_USA_Intersection_EP0", "v1.0", 1))


def generate_study_recordings(out_dir: Path, seconds: float = 900.0) -> list[dict]:
    """Write both scenarios into `out_dir` (`seconds` of training traffic each, half as much
    held out); returns the generator's summaries."""
    return [generate(out_dir, scenario, layout, train_s=seconds, val_s=seconds / 2, seed=seed)
            for scenario, layout, seed in STUDY_SCENARIOS]
