"""How long the paper study takes a person, measured in Chromium beside `tomstudy estimate`.

Serves the paper study from its shipped bundle (`tomstudy serve`, a fresh SQLite file) and walks
one participant in Debian's chromium in real time (no fake clock). For each of the first
--trials trials it times, by the wall clock, the clips from the trial screen appearing to
"Make predictions" becoming available (the clips played once, as the page really plays them),
and compares that with the estimate's clip time of the same bank trial. The realistic figure
is then the estimate's clip time scaled by the measured ratio plus reading and clicking at the
stated pace (230 words/min and 2.5 s per click; slow: 180 words/min and 4 s per click).

With --full the walk goes on to the end at that pace (it waits words/wpm on each text and
--click-s before each click, so it takes as long as a person would: about 40 minutes) and
prints the server's own duration_min from the participants export.

    .venv/bin/python benchmarks/study_time.py [--trials 3] [--full] [--click-s 2.5] [--wpm 230]
"""

import argparse
import csv
import io
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app.bank.served import served_bundle  # noqa: E402
from app.settings import Settings  # noqa: E402
from app.study.config import load_study_config  # noqa: E402
from app.study.estimate import (  # noqa: E402
    MEDIAN_PACE,
    SLOW_PACE,
    Pace,
    clip_seconds,
    estimate,
    player_timing,
    study_estimate,
)
from tests.conftest import (  # noqa: E402
    REPO,
    SmallStudy,
    free_port,
    researcher_get,
    start_server,
)
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS  # noqa: E402
from tests.e2e.pages import (  # noqa: E402
    ONWARD,
    VIEWPORT,
    answer_survey,
    current_state,
    fresh_recruitment,
    place,
    shown_screen,
    visible,
)

STUDY = "paper_study"


class Walker:
    """One participant in chromium at a stated pace (real time: nothing is sped up)."""

    def __init__(self, page, pace: Pace, paced: bool):
        self.page, self.pace, self.paced = page, pace, paced

    def read(self, selector: str) -> None:
        """Wait as long as reading the text of `selector` takes at the pace."""
        if self.paced:
            time.sleep(len(self.page.inner_text(selector).split()) / self.pace.words_per_minute
                       * 60)

    def click(self, selector: str) -> None:
        """Click after the pace's time per click."""
        if self.paced:
            time.sleep(self.pace.seconds_per_click)
        self.page.click(selector)

    def consent_and_instructions(self) -> None:
        visible(self.page, "consent")
        self.read("#consent-text")
        self.page.check("#consent-check")
        self.click("#consent-agree")
        visible(self.page, "instructions")
        self.read("#instructions-text")
        self.click("#instructions-done")

    def trial(self) -> tuple[dict, float]:
        """Watch the trial's clips once (timed), then answer it at the pace; the trial's
        payload and the seconds its clips took."""
        state = current_state(self.page, STUDY)["step"]
        started = time.monotonic()
        self.page.wait_for_selector("#start-predicting:not([disabled])", timeout=180_000)
        watched = time.monotonic() - started
        self.click("#start-predicting")
        for start in range(len(state["start_states"])):
            for step in range(state["steps_to_predict"]):
                if self.paced:
                    time.sleep(self.pace.seconds_per_click)
                place(self.page, state, start, [step], think_ms=0)
            self.click("#next")
        if state.get("feedback"):  # a practice trial ends with one screen per start position
            self.page.wait_for_selector("#trial-caption:has-text('Practice feedback')")
            for _ in state["start_states"]:
                self.click("#next")
        self.page.wait_for_function("() => document.querySelector('#screen-trial').hidden")
        return state, watched

    def onward(self) -> str:
        """Through the screens that only ask to go on (reading each); the next real screen."""
        while (shown := shown_screen(self.page)) in ONWARD:
            self.read(f"#screen-{shown}")
            self.click(ONWARD[shown])
            self.page.wait_for_function(
                "s => document.querySelector(`#screen-${s}`).hidden", arg=shown)
        return shown


def server_minutes(base: str) -> float:
    """duration_min of the one finished session, from the participants export."""
    r = researcher_get(f"{base}/api/researcher/export/participants.csv",
                       params={"study_id": STUDY})
    r.raise_for_status()
    rows = [row for row in csv.DictReader(io.StringIO(r.text)) if row["duration_min"]]
    return float(rows[-1]["duration_min"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=3, help="trials whose clips are timed")
    parser.add_argument("--full", action="store_true", help="walk the whole study at the pace")
    parser.add_argument("--wpm", type=float, default=MEDIAN_PACE.words_per_minute)
    parser.add_argument("--click-s", type=float, default=MEDIAN_PACE.seconds_per_click)
    args = parser.parse_args()
    pace = Pace(words_per_minute=args.wpm, seconds_per_click=args.click_s)
    settings = Settings(configs_dir=REPO / "study_configs")
    config = load_study_config(settings, STUDY)
    bank = served_bundle(settings, STUDY).bank
    timing = player_timing()
    found = study_estimate(config, bank, timing, pace)
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as root:
        study = SmallStudy(Path(root), REPO / "study_configs", STUDY)
        port = free_port()
        proc = start_server(study, f"sqlite:///{root}/study.db", port, log=Path(root) / "log")
        base = f"http://127.0.0.1:{port}"
        try:
            with sync_playwright() as playwright:
                browser = playwright.chromium.launch(executable_path=str(CHROMIUM),
                                                     args=CHROMIUM_ARGS)
                page = browser.new_page(viewport=VIEWPORT)
                walker = Walker(page, pace, paced=args.full)
                page.goto(f"{base}/s/{STUDY}?{fresh_recruitment()}")
                walker.consent_and_instructions()
                timed = []
                while walker.onward() == "trial" and (args.full or len(timed) < args.trials):
                    shown, watched = walker.trial()
                    if len(timed) < args.trials:
                        clips = [*shown["examples"], shown["segment"]]
                        expected = sum(clip_seconds(len(c["positions"]) - 1, timing)
                                       for c in clips)
                        timed.append((watched, expected))
                        print(f"trial {len(timed)}: clips {watched:.1f} s in chromium, "
                              f"{expected:.1f} s estimated ({watched / expected:.3f})")
                if args.full:
                    answer_survey(page)
                    visible(page, "done")
                    print(f"server's duration_min of the walk at {pace.describe()}: "
                          f"{server_minutes(base):.1f}")
                browser.close()
        finally:
            proc.terminate()
            proc.wait(timeout=10)
    ratio = sum(w for w, _ in timed) / sum(e for _, e in timed)
    print(f"clips measured / estimated over {len(timed)} trials: {ratio:.3f}")
    for name, chosen in (("median", pace), ("slow", SLOW_PACE)):
        e = estimate(found.work, chosen)
        realistic = e.total_min + e.clips_min * (ratio - 1)
        print(f"{name} participant ({chosen.describe()}): {realistic:.1f} min with the measured "
              f"clip time ({e.total_min:.1f} estimated)")
    print(f"advertised: {found.advert.minutes} min, {found.advert.pay or 'no pay set'}")


if __name__ == "__main__":
    main()
