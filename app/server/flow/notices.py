"""What a participant reads when the study turns them away, in plain language.

Every refusal a participant can meet (a link without its platform's details, a finished or
running attempt, a closed or full study, an unknown study, the study open in another tab)
gets a heading and a text that says what to do on the recruiting platform. The API answer
carries it as `notice` beside the `field: message` detail, the page shows it, and field
names stay in the API and the logs.
"""

from app.study.errors import Notice

_PLATFORM = {"prolific": "Prolific", "mturk": "MTurk"}
_OPEN_AGAIN = {
    "prolific": "Please go back to Prolific and open the study again with the button on "
                "its study page.",
    "mturk": "Please go back to the HIT on MTurk and open the study from there.",
}
_ASK = {
    "prolific": "send the researchers a message through Prolific.",
    "mturk": "contact the requester through MTurk.",
}
_HELP = {platform: f"If this keeps happening, {ask}" for platform, ask in _ASK.items()}
_ASK_LAB = "ask the person running the study."
_RETURN = {
    "prolific": "Please return the study on Prolific (the Return button on the study page) "
                "so that your place goes to someone else. Returning does not count against "
                "you.",
    "mturk": "Please return the HIT on MTurk so that it goes to someone else.",
}
_LAB = "Please ask the person running the study."


def _platform_name(platform: str) -> str:
    return _PLATFORM.get(platform, "the recruiting platform")


def link_incomplete(platform: str) -> Notice:
    """The link lacks (or garbles) the details the platform adds to it."""
    return Notice("This link is incomplete",
                  f"The link that opened this page is missing details that "
                  f"{_platform_name(platform)} adds to it, so the study cannot start. "
                  f"{_OPEN_AGAIN.get(platform, _LAB)} {_HELP.get(platform, '')}".strip())


def other_study(platform: str) -> Notice:
    """The link names another study of the platform."""
    return Notice("This link belongs to another study",
                  f"The link that opened this page was made for a different study. "
                  f"{_OPEN_AGAIN.get(platform, _LAB)} {_HELP.get(platform, '')}".strip())


def not_on_prolific() -> Notice:
    """Prolific has no submission of this study by this person under the link's session."""
    return Notice("Prolific does not know this link",
                  "We asked Prolific about the link that opened this page, and it has no "
                  "place in this study for it, so the study cannot start from it. "
                  f"{_OPEN_AGAIN['prolific']} {_HELP['prolific']}")


def hit_preview() -> Notice:
    """An MTurk HIT preview tried to start the study."""
    return Notice("Accept the HIT first",
                  "This is the preview of the HIT. Please accept the HIT on MTurk; the "
                  "study then starts in this frame.")


def preview_link_outdated() -> Notice:
    """A lab member's preview link with a key that is not (or no longer) this study's."""
    return Notice("This preview link is out of date",
                  "Researchers: copy the current preview link from the researcher dashboard "
                  "or run `tomstudy preview-link`. Participants never use preview links.")


def already_taken_part(platform: str) -> Notice:
    """This person finished (or ended) the study under another attempt."""
    return Notice("You have already taken part",
                  "Our records show that you have already taken part in this study under "
                  f"another {_platform_name(platform)} session, and each person can take "
                  f"part once. {_RETURN.get(platform, _LAB)} If you finished the study and "
                  f"still need your completion code, {_ASK.get(platform, _ASK_LAB)}")


def running_elsewhere(platform: str, minutes: float) -> Notice:
    """Another attempt of this person is still running."""
    return Notice("The study is already running for you",
                  f"You started this study under another {_platform_name(platform)} "
                  "session that is still running. Please continue in the browser window "
                  "where you started it. If you closed that window, you can open the study "
                  f"again after about {round(minutes)} minutes without activity.")


def started_twice() -> Notice:
    """Two starts of one person crossed."""
    return Notice("The study was opened twice at once",
                  "Please reload this page; the study continues where you are.")


def closed(platform: str) -> Notice:
    """The study takes no new participants."""
    return Notice("This study is closed",
                  f"The study is no longer taking new participants. "
                  f"{_RETURN.get(platform, _LAB)} Thank you for your interest.")


def full(platform: str) -> Notice:
    """The study has as many counted sessions as it may."""
    return Notice("This study is full",
                  f"The study already has all the participants it needs. "
                  f"{_RETURN.get(platform, _LAB)} Thank you for your interest.")


def unknown_study() -> Notice:
    """The link names no study this server runs."""
    return Notice("This study is not available",
                  "The link does not lead to a study that runs here: it may be mistyped or "
                  "out of date. Please go back to the page where you found the link (on "
                  "Prolific or MTurk: the study's page) and open it again from there. If "
                  "that does not help, message the researchers through that platform.")


def open_in_another_tab() -> Notice:
    """Another tab of this browser (or another device) holds the session."""
    return Notice("The study is open in another tab",
                  "This study is already open in another tab or window. Please continue "
                  "there and close this one. If the other tab is closed or not working, you "
                  "can continue here instead: everything you have answered and clicked so "
                  "far is kept.", action="takeover")


def busy() -> Notice:
    """The study runs as many unfinished sessions as it takes at once (503, Retry-After)."""
    return Notice("The study is busy",
                  "Many people are taking this study right now. Please wait a few minutes "
                  "and reload this page; nothing is lost by waiting.")


def replaced() -> Notice:
    """A newer attempt of the same person took this session over (410)."""
    return Notice("The study continues elsewhere",
                  "You opened the study again in another tab or attempt, and it continues "
                  "there. This page can no longer save answers: please close it.")


def study_changed(platform: str) -> Notice:
    """The study's trials changed after this session started (410)."""
    return Notice("The study was changed",
                  f"The researchers changed the study after you started, so this session "
                  f"cannot continue. Your answers so far are saved. "
                  f"{_RETURN.get(platform, _LAB)} {_HELP.get(platform, '')}".strip())
