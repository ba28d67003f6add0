"""The consent form: typed sections a review board asks for, rendered with the estimate's time
and pay; production refuses a form that still holds a lab's [PLACEHOLDER] (naming the field)
or a hand-typed time; the shipped bundle's older config still validates and dumps as before."""

import pytest
import yaml

from app.configio import load_yaml_model
from app.main import NotServable, create_app, servable_study
from app.settings import Settings
from app.study.config import ConsentForm, StudyConfig, load_study_config
from app.study.consent import Advert, consent_problem, consent_sections
from tests.conftest import FILLED_CONSENT, REPO, local_client
from tests.server.flow import Participant

STRONG = "s" * 40
PRODUCTION = {"production": True, "admin_token": STRONG, "rate_limit_starts": "30/minute",
              "rate_limit_requests": "3000/minute"}


def paper_config() -> StudyConfig:
    return load_study_config(Settings(), "paper_study")


def with_consent(config: StudyConfig, **changes) -> StudyConfig:
    """`config` with some consent fields changed (validated again)."""
    data = config.model_dump(mode="json")
    data["consent"] = {**data["consent"], **changes}
    return StudyConfig.model_validate(data)


def test_the_shipped_studies_carry_marked_placeholders_production_refuses():
    for study in ("paper_study", "interaction_study"):
        config = load_study_config(Settings(), study)
        assert config.consent is not None
        assert consent_problem(config, production=False) is None
        problem = consent_problem(config, production=True)
        assert problem == ("consent.institution: still holds the placeholder [YOUR INSTITUTION]; "
                           "write your own")


@pytest.mark.parametrize("field, value, named", [
    ("ethics_approval", "Approved by [REVIEW BOARD].", "consent.ethics_approval"),
    ("investigators", [{"name": "A B", "email": "[INVESTIGATOR EMAIL]"}],
     "consent.investigators.0.email"),
    ("retention", "Kept for [RETENTION PERIOD].", "consent.retention"),
    ("purpose", "It takes about 25 minutes.", "consent.purpose"),
])
def test_production_names_the_field_that_is_not_filled_in(field, value, named):
    config = with_consent(paper_config(), **(FILLED_CONSENT | {field: value}))
    problem = consent_problem(config, production=True)
    assert problem.startswith(f"{named}: ")
    assert consent_problem(with_consent(paper_config(), **FILLED_CONSENT), True) is None


def test_a_typed_time_in_the_description_and_pay_without_a_rate_are_refused():
    filled = with_consent(paper_config(), **FILLED_CONSENT)
    typed = filled.model_copy(update={"description": "About 25 minutes."})
    assert consent_problem(typed, True).startswith("description: states the time by hand")
    unpaid = filled.model_copy(update={"recruitment": filled.recruitment.model_copy(
        update={"hourly_pay": None})})
    assert consent_problem(unpaid, False) == ("description: uses {pay} but "
                                              "recruitment.hourly_pay is not set")


def test_production_needs_the_typed_form_not_only_free_text():
    data = paper_config().model_dump(mode="json")
    del data["consent"]
    data["consent_text"] = "We study robots. Participation is voluntary."
    legacy = StudyConfig.model_validate(data)
    assert consent_problem(legacy, False) is None
    assert consent_problem(legacy, True).startswith("consent: a production study needs")


def test_an_email_is_an_address_or_a_marked_placeholder():
    with pytest.raises(ValueError, match="email"):
        ConsentForm.model_validate(FILLED_CONSENT | {"investigators": [
            {"name": "A", "email": "ask the lab"}]})


def test_the_shipped_bundles_older_config_validates_and_dumps_without_the_new_keys():
    frozen = REPO / "study_configs/bundles/paper_study/configs/paper_study.yaml"
    config = load_yaml_model(frozen, StudyConfig)
    dump = config.model_dump(mode="json")
    assert "consent" not in dump and "hourly_pay" not in dump["recruitment"]
    assert dump["consent_text"] == yaml.safe_load(frozen.read_text())["consent_text"]


def test_every_section_is_on_the_page_with_the_estimates_time_and_pay():
    config = with_consent(paper_config(), **FILLED_CONSENT)
    sections = consent_sections(config, Advert(41, "GBP 6.15", "GBP 9.00 per hour"))
    text = {s["heading"]: s["text"] for s in sections}
    assert list(text) == ["What this study is", "Who is running it", "Ethics approval",
                          "Time and payment", "What we record",
                          "How long we keep your data and who sees it",
                          "Taking part is voluntary", "Stopping and withdrawing",
                          "Risks and benefits"]
    assert FILLED_CONSENT["institution"] in text["Who is running it"]
    for person in FILLED_CONSENT["investigators"]:
        assert f"{person['name']} ({person['role']}), {person['email']}" in text[
            "Who is running it"]
    assert "about 41 minutes" in text["Time and payment"]
    assert "GBP 6.15 (GBP 9.00 per hour) through Prolific" in text["Time and payment"]
    for field in ("ethics_approval", "purpose", "recorded", "retention", "voluntary",
                  "withdrawal", "risks"):
        assert FILLED_CONSENT[field] in text.values()


def test_the_server_sends_the_sections_and_refuses_placeholders_in_production(small_study,
                                                                             tmp_path):
    configs = small_study.configs_dir
    settings = small_study.settings(f"sqlite:///{tmp_path / 'c.db'}", **PRODUCTION)
    with local_client(create_app(settings, [small_study.study_id])) as client:
        p = Participant(client, small_study.study_id)
        p.start()
        step = p.state()["step"]
        advert = client.app.state.studies[small_study.study_id].estimate().advert
        assert step["sections"] == consent_sections(load_yaml_model(
            configs / f"{small_study.study_id}.yaml", StudyConfig), advert)
        assert f"about {advert.minutes} minutes" in str(step["sections"])
    placeholder = tmp_path / "configs"
    placeholder.mkdir()
    (placeholder / "worlds").symlink_to(configs / "worlds")
    data = yaml.safe_load((configs / f"{small_study.study_id}.yaml").read_text())
    data["consent"] = data["consent"] | {"ethics_approval": "Approved ([APPROVAL ID])."}
    (placeholder / f"{small_study.study_id}.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(NotServable) as refused:
        servable_study(settings.model_copy(update={"configs_dir": placeholder}),
                       small_study.study_id)
    assert str(refused.value) == (
        f"refusing to serve study {small_study.study_id} in production mode: "
        "consent.ethics_approval: still holds the placeholder [APPROVAL ID]; write your own")
