"""The two INTERACTION scenarios the recordings tests generate, and a recorded world's config
on one of them."""

from app.recordings.config import RecordedConfig

ROUNDABOUT, INTERSECTION = "DR_USA_Roundabout_FT", "DR_USA_Intersection_EP0"


def recorded_config(scenario: str, **extra) -> RecordedConfig:
    """A recorded world's config on `scenario`'s INTERACTION files (`extra` keys added)."""
    return RecordedConfig.model_validate({
        "kind": "recorded", "source": {"format": "interaction", "path": "INTERACTION",
                                       "scenario": scenario}, **extra})
