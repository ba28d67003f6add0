"""What every participant request needs besides the database: one loaded study."""

from dataclasses import dataclass, field

from app.bank.model_answers import ModelAnswers
from app.prediction_view import VIEW_FIELDS, PredictionView, prediction_view
from app.study.config import StudyConfig
from app.study.estimate import StudyEstimate, study_estimate
from app.study.trials import TrialBank


@dataclass(frozen=True)
class StudyContext:
    """A study's config, bank and models, and the server's per-study secrets and rules."""

    study_id: str
    config: StudyConfig
    bank: TrialBank
    model_answers: ModelAnswers
    config_sha256: str = ""  # of the validated config (config.config_sha256)
    preview_key: str = field(default="", repr=False)  # opens pilot sessions (recruitment.py)
    trust_client_clock: bool = False  # pilots with bots only; never in production
    # trial id -> the trial's static browser JSON, encoded once (see app/server/flow/state.py)
    trial_json: dict[str, str] = field(default_factory=dict, compare=False, repr=False)
    views: dict[str, PredictionView] = field(default_factory=dict, compare=False, repr=False)
    # the estimate of the config it was computed from (a test may serve a changed config)
    estimates: dict[int, StudyEstimate] = field(default_factory=dict, compare=False, repr=False)

    def view(self, world: str) -> PredictionView:
        """The prediction screen's scale of `world`, from its bank (computed once)."""
        if world not in self.views:
            self.views[world] = prediction_view(
                self.bank.world(world).model_dump(include=VIEW_FIELDS))
        return self.views[world]

    def estimate(self) -> StudyEstimate:
        """The study's time and pay from its bank and texts (app/study/estimate.py), once."""
        key = id(self.config)
        if key not in self.estimates:
            self.estimates.clear()
            self.estimates[key] = study_estimate(self.config, self.bank)
        return self.estimates[key]
