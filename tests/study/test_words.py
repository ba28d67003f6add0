"""The words a participant reads name the study's own agents (issue 33 item 1).

Every shipped study (the paper study, shrunk as the small study; the interaction study on
generated recordings) and a study of the lab's hallway world is served, its pages rendered and
a session walked through the API: no noun of another world appears in what the participant
reads, the page's HTML text and labels, the scripts' texts (#study-words) and every served
prose step (consent, instructions, part screens, survey, ending).
"""

import re
from html.parser import HTMLParser
from pathlib import Path

import pytest
import yaml

from app.configio import ConfigError, load_yaml_model
from app.study.config import StudyConfig, config_sha256, load_study_config
from app.study.words import ParticipantWords, participant_texts
from tests.conftest import (
    REPO,
    SMALL_SEEDS,
    SMALL_TRAINING,
    SmallStudy,
    build_bundle_of,
    cached_build,
    write_small_configs,
)
from tests.server.flow import (
    PART_PHASES,
    TRIAL_PHASES,
    Participant,
    make_client,
    new_id,
    page_json,
)

# the nouns of the robot-and-person worlds, which a study of cars never says
ROBOT_WORLD = re.compile(r"\b(robots?|persons?|humans?|goals?|obstacles?)\b", re.I)
CAR_WORLD = re.compile(r"\bcars?\b", re.I)  # which the robot's instructions and demo never say
PROSE_KEYS = ("title", "text", "heading", "message", "sections", "questions", "options")
HALLWAY_STUDY = "hallway_study"


class ReadText(HTMLParser):
    """What a participant reads on a page: its text outside scripts, and its labels."""

    LABELS = ("aria-label", "title", "alt", "placeholder")

    def __init__(self):
        super().__init__()
        self.parts, self.in_script = [], False

    def handle_starttag(self, tag, attrs):
        self.in_script = tag in ("script", "style")
        self.parts += [value for name, value in attrs if name in self.LABELS and value]

    def handle_endtag(self, tag):
        self.in_script = False

    def handle_data(self, data):
        if not self.in_script and data.strip():
            self.parts.append(" ".join(data.split()))


def page_reads(html: str) -> str:
    """The page's text and labels, and the scripts' texts that name the agents."""
    reader = ReadText()
    reader.feed(html)
    texts = page_json(html, "study-words")["texts"]
    return " ".join(" ".join([*reader.parts, *texts.values()]).split())  # nbsp: a space


def prose(value) -> list[str]:
    """Every text in a served step (titles, texts, sections, questions), never its scene."""
    if isinstance(value, str):
        return [value]
    if isinstance(value, list):
        return [text for item in value for text in prose(item)]
    if isinstance(value, dict):
        return [text for key, item in value.items() if key in PROSE_KEYS for text in prose(item)]
    return []


def walked_prose(client, study_id: str) -> str:
    """The prose of every step of one session walked to its end (trials answered)."""
    p = Participant(client, study_id)
    p.start()
    texts, state = [], p.state()
    texts += prose(state["step"])
    assert p.consent().status_code == 200
    texts += prose(p.state()["step"])
    assert p.post("instructions", {"submission_id": new_id()}).status_code == 200
    state = p.state()
    while state["phase"] != "survey":
        if state["phase"] in PART_PHASES:
            texts += prose(state["step"])
            p.pass_screens()
        elif state["phase"] in TRIAL_PHASES:
            p.answer_trial()
        state = p.state()
    texts += prose(state["step"])
    texts += prose(p.survey()["step"])
    return "\n".join(texts)


def served(study: SmallStudy, tmp_path: Path) -> tuple[str, str]:
    """The study page's reading and a walked session's prose, from a fresh server."""
    with make_client(study, f"sqlite:///{tmp_path / 'words.db'}") as client:
        return page_reads(client.get(f"/s/{study.study_id}").text), walked_prose(
            client, study.study_id)


def build_hallway_study(root: Path) -> SmallStudy:
    """The small study's design on the lab's hallway world alone (GENERATED, not real, robot
    logs), its config saying nothing of words or demo: import, train 2 epochs, bank, bundle."""
    from app.learning.config import TrainConfig
    from app.learning.family import train_family
    from app.recordings.synthetic_logs import generate_logs
    from app.worlds.registry import build_world

    study = SmallStudy(root / "var", root / "configs", HALLWAY_STUDY)
    write_small_configs(study.configs_dir, HALLWAY_STUDY)
    path = study.configs_dir / f"{HALLWAY_STUDY}.yaml"
    config = yaml.safe_load(path.read_text())
    config |= {"worlds": ["hallway"], "counterbalance_world_order": False, "exploratory_worlds": {},
               "title": "How will the robot move next?",
               "instructions_text": "Watch the robot (blue) among people, then predict its "
                                    "next three moves from five start positions.",
               "world_intros": {"hallway": {
                   "title": "The hallway",
                   "text": "Recordings of a robot in a hallway; the orange, striped person "
                           "is the one nearest to it."}}}
    path.write_text(yaml.safe_dump(config))
    layout = study.layout
    generate_logs(layout.recordings() / "lab" / "logs.csv", recordings=24, seconds=60.0, seed=3)
    build_world("hallway", study.configs_dir / "worlds" / "hallway.yaml").import_recordings(layout)
    train_family(layout, ["hallway"], SMALL_SEEDS, TrainConfig(**SMALL_TRAINING), workers=1,
                 say=lambda _: None)
    build_bundle_of(study)
    return study


@pytest.fixture(scope="module")
def hallway_study() -> SmallStudy:
    """`build_hallway_study`, cached as the small study is."""
    return cached_build("tomstudy-hallway-study", ["app/recordings", "app/worlds", "app/bank",
                                                   "app/study/config.py", "study_configs"],
                        build_hallway_study)


# ---------------------------------------------------------------- the config

def test_words_and_demo_default_to_the_paper_studys_and_are_left_out_of_its_dump():
    paper = load_yaml_model(REPO / "study_configs" / "paper_study.yaml", StudyConfig)
    assert paper.words == ParticipantWords() and paper.demo == "obstacle"
    dumped = paper.model_dump(mode="json")
    assert "words" not in dumped and "demo" not in dumped
    # set to the defaults, they dump (and hash) as if left out
    same = StudyConfig.model_validate(dumped | {"words": {"agent": "robot"}, "demo": "obstacle"})
    assert config_sha256(same) == config_sha256(paper)


def test_the_interaction_study_names_two_cars_and_shows_the_road_demo(tmp_path):
    from app.settings import Settings

    config = load_study_config(Settings(configs_dir=REPO / "study_configs"), "interaction_study")
    assert (config.words.agent, config.words.other) == ("blue car", "orange car")
    assert config.demo == "road"
    assert config.model_dump(mode="json")["words"]["agent_key"] == "B"


@pytest.mark.parametrize(("words", "field"), [
    ({"agent_key": "RB"}, "words.agent_key"), ({"agent": "Blue <b>car</b>"}, "words.agent"),
    ({"other": "robot"}, "words"), ({"other_key": "R"}, "words")])
def test_bad_words_are_refused_naming_the_field(tmp_path, words, field):
    data = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(data | {"words": words}))
    with pytest.raises(ConfigError, match=rf"study.yaml: {re.escape(field)}: "):
        load_yaml_model(path, StudyConfig)


def test_the_scripts_texts_say_the_studys_nouns():
    texts = participant_texts(ParticipantWords(agent="blue car", other="orange car",
                                               agent_key="B", other_key="O"))
    assert texts["predict_prompt"] == ("Click where the blue car will be after each of the "
                                       "next {steps} steps.")
    assert texts["demo_clip"] == ("Illustration: a clip shows the blue car (B) and the orange "
                                  "car (O) moving")
    assert not any(ROBOT_WORLD.search(t) for t in texts.values())


# ---------------------------------------------------------------- every study, served

def test_the_paper_study_says_robot_and_person_as_before_and_never_car(small_study, tmp_path):
    page, _ = served(small_study, tmp_path)  # its highway intro and consent do say cars
    for today in ("R the robot (blue, solid)", "H the person (orange, striped)",
                  "R robot H person", "The robot appears at a start position; the person "
                  "stays where it is.", "Demonstration clip of the robot and the person moving",
                  "Illustration: a clip shows the robot (R) and the person (H) moving"):
        assert today in page
    assert not CAR_WORLD.search(page), CAR_WORLD.findall(page)


def test_the_interaction_study_says_cars_everywhere(interaction_study, tmp_path):
    page, walked = served(interaction_study, tmp_path)
    found = ROBOT_WORLD.findall(page) + ROBOT_WORLD.findall(walked)
    assert found == []
    assert "B the blue car (solid)" in page
    assert "Click where the blue car will be" in page
    assert "the blue car" in walked and "orange" in walked


def test_the_hallway_world_says_robot_and_person(hallway_study, tmp_path):
    page, walked = served(hallway_study, tmp_path)
    assert not CAR_WORLD.search(page + walked), CAR_WORLD.findall(page + walked)
    assert "the robot" in page and "the person" in page
