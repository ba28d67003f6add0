"""GENERATED, NOT REAL DATA: the interaction study's two scenarios as INTERACTION-format files.

For demos, tests and labs that have not downloaded the dataset yet: app/recordings/
synthetic_tracks.py's generated traffic, a roundabout in the v1.2 layout and an intersection in the
v1.0 layout, each with its lanelet2-style map, where study_configs/worlds/roundabout.yaml and
intersection.yaml look for the real download. Nothing here is a recording.
"""

from pathlib import Path

from app.recordings.synthetic_tracks import (
    REAL_SIZE_ARRIVALS_PER_ARM_MIN,
    generate,
    generate_recordings,
)

# scenario, devkit layout, seed: one of each layout, so a study exercises both readers
STUDY_SCENARIOS = (("DR_USA_Roundabout_FT", "v1.2", 0), ("DR_USA_Intersection_EP0", "v1.0", 1))
FILE_SEEDS = 1000  # scenario k's recording j: seed k * FILE_SEEDS + j


def generate_study_recordings(out_dir: Path, seconds: float = 900.0, files: int | None = None,
                              arrivals_per_arm_min: float | None = None) -> list[dict]:
    """Write both scenarios into `out_dir`; returns the generator's summaries. Without `files`:
    a v1.2 roundabout and a v1.0 intersection, `seconds` of training traffic each and half as
    much held out. With `files`: both in the v1.0 layout, `files` recordings of `seconds`
    each, at `arrivals_per_arm_min` (default: real size, REAL_SIZE_ARRIVALS_PER_ARM_MIN)."""
    if files is None:
        return [generate(out_dir, scenario, layout, train_s=seconds, val_s=seconds / 2,
                         seed=seed, arrivals_per_arm_min=arrivals_per_arm_min)
                for scenario, layout, seed in STUDY_SCENARIOS]
    rate = arrivals_per_arm_min or REAL_SIZE_ARRIVALS_PER_ARM_MIN
    return [generate_recordings(out_dir, scenario, files, seconds, seed * FILE_SEEDS, rate)
            for scenario, _, seed in STUDY_SCENARIOS]
