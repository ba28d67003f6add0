"""What the participant pages call the two agents, and which demo the instructions show.

A study's `words` name the agent whose moves are predicted and the other one, in every text a
participant reads that is not the config's own prose (the instructions page, the trial
legend, the prompts, the practice feedback, the demo's captions, the canvases' labels and the
one-letter tags drawn beside the agents). The defaults are the paper study's (a robot and a
person), so a config without `words` reads as every study did before the key existed.
"""

from typing import Literal

from pydantic import Field, model_validator

from app.configio import StrictModel

# the instructions' illustration (frontend/static/js/demo.js): `obstacle` a disc robot and a
# person on a field with an obstacle and two goals (the paper study's), `road` two cars on a
# drawn road with lane lines and a side road (recorded traffic); never study data
DemoName = Literal["obstacle", "road"]
DEFAULT_DEMO: DemoName = "obstacle"
_NOUN = r"^[a-z][a-z -]{0,29}$"  # said as "the <noun>" mid-sentence: lower case, no markup
_KEY = r"^[A-Z]$"


class ParticipantWords(StrictModel):
    """The two agents as the participant pages name them.

    `agent` is the one whose moves are predicted, `other` the one beside it; each is said as
    "the <noun>" and "the <noun>'s", so a noun is lower case ("blue car", not "Blue car").
    `*_key` is its one-letter tag on the canvas and in the legends; `*_look` how the
    instructions' legend describes its drawing (the colours are the scene palette's).
    """

    # the agent whose moves are predicted, as every page names it (lower case noun, said as "the
    # <noun>")
    agent: str = Field(default="robot", pattern=_NOUN)
    # the agent beside it, named the same way (must differ from agent)
    other: str = Field(default="person", pattern=_NOUN)
    # the agent's one-letter tag on the canvas and in the legends (an upper-case letter)
    agent_key: str = Field(default="R", pattern=_KEY)
    # the other agent's one-letter tag (an upper-case letter, not agent_key)
    other_key: str = Field(default="H", pattern=_KEY)
    # how the instructions' legend describes the agent's drawing (1-40 characters; the colours are
    # the scene palette's)
    agent_look: str = Field(default="blue, solid", min_length=1, max_length=40)
    # how the legend describes the other agent's drawing (1-40 characters)
    other_look: str = Field(default="orange, striped", min_length=1, max_length=40)

    @model_validator(mode="after")
    def _told_apart(self) -> "ParticipantWords":
        if self.agent == self.other:
            raise ValueError("other: must differ from agent (the pages tell the two apart)")
        if self.agent_key == self.other_key:
            raise ValueError("other_key: must differ from agent_key")
        return self


def participant_texts(words: ParticipantWords) -> dict[str, str]:
    """The scripts' texts that name an agent, in the study's words; the page fills each
    {placeholder} ({steps}, {where}, {k}, {n}) where it shows the text."""
    agent, other = words.agent, words.other
    return {
        "predict_prompt": f"Click where the {agent} will be after each of the next {{steps}} "
                          "steps.",
        "practice_feedback": f"Compare your clicks (black rings) with where the {agent} went "
                             "from there (blue dots).",
        "relocated_start": f"{{where}}: the {agent} is placed somewhere else; the grey dots "
                           "show its path in the clip, not its way here.",
        "cursor_not_moved": "Move the cross with the arrow keys first: it starts at the "
                            f"{agent}'s current position.",
        "demo_clip": f"Illustration: a clip shows the {agent} ({words.agent_key}) and the "
                     f"{other} ({words.other_key}) moving",
        "demo_own_start": "Start position 1 of {n}: where the clip ended. Click where the "
                          f"{agent} will be after each of the next steps, inside the shaded "
                          "circle",
        "demo_moved_start": f"Start position {{k}} of {{n}}: the {agent} is moved elsewhere "
                            "(its path in the clip is grey); predict from there",
    }


def page_words(words: ParticipantWords, demo: DemoName) -> dict:
    """What a page that draws a scene carries as #study-words (frontend/static/js/words.js)."""
    return {"words": words.model_dump(), "texts": participant_texts(words), "demo": demo}
