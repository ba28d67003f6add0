"""The interaction study (recorded worlds on GENERATED recordings) in Debian's chromium.

A participant walks both parts by clicking; each part's drawing, the clips and the small map
show the recorded road; the clip follows the robot car; the map's driven area has no seams and
its lines are drawn in their styles.
"""

import json
import math
import re
import sqlite3
import time
from contextlib import closing
from pathlib import Path

import pytest
import yaml

from tests.conftest import INTERACTION_STUDY
from tests.e2e.pages import (
    JS,
    ONWARD,
    VIEWPORT,
    answer_survey,
    answer_trial,
    canvas_view,
    consent_and_instructions,
    contrast,
    current_state,
    fresh_recruitment,
    page_token,
    planned_path,
    press_on,
    robot_outline,
    shown_screen,
    start_predicting,
    visible,
)

pytestmark = [pytest.mark.browser, pytest.mark.slow]

RECORDED_MAP = (JS / "recorded_map.js").read_text()
# share of a canvas' pixels in the recorded road's colour (the page's palette)
ROAD_SHARE = """sel => {
    const canvas = document.querySelector(sel);
    const road = JSON.parse(document.getElementById("scene-palette").textContent).map.road;
    const want = [1, 3, 5].map((i) => parseInt(road.slice(i, i + 2), 16));
    const data = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
    let hits = 0;
    for (let i = 0; i < data.length; i += 4) {
        if (data[i] === want[0] && data[i + 1] === want[1] && data[i + 2] === want[2]) hits += 1;
    }
    return hits / (data.length / 4);
}"""
FOLLOW_CHECK_MS = (900, 2100)  # two moments of the practice trial's first clip


def hex_rgb(colour: str) -> list[int]:
    return [int(colour[i:i + 2], 16) for i in (1, 3, 5)]


def near_on_path(point, path, bounds, half) -> float:
    """Distance (m) from `point` to the nearest view centre that follows `path` (robot
    positions, interpolated) kept `half` = (x, y) metres inside the scene's bounds."""
    best = math.inf
    for a, b in zip(path, path[1:], strict=False):
        for f in (k / 40 for k in range(41)):
            p = [a[i] + f * (b[i] - a[i]) for i in (0, 1)]
            lo = (bounds["x_min_m"] + half[0], bounds["y_min_m"] + half[1])
            hi = (bounds["x_max_m"] - half[0], bounds["y_max_m"] - half[1])
            centre = [min(max(p[i], lo[i]), hi[i]) if lo[i] < hi[i] else (lo[i] + hi[i]) / 2
                      for i in (0, 1)]
            best = min(best, math.dist(point, centre))
    return best


def view_centre(page) -> tuple[list[float], float, tuple[float, float]]:
    """The trial canvas' view: its centre (m), its px per metre and its CSS size."""
    scale, origin_x, origin_y = canvas_view(page)
    width, height = page.eval_on_selector("#trial-canvas", "c => [c.clientWidth, c.clientHeight]")
    return [(width / 2 - origin_x) / scale, (height / 2 - origin_y) / scale], scale, (width, height)


def check_the_clip_follows_the_robot(page, trial: dict) -> None:
    """At two moments of the first clip: view_span_m across the shorter side, centred on the
    robot (or held inside the scene), and the map scrolled between them."""
    scene = trial["scene"]
    robot = [step[0] for step in trial["examples"][0]["positions"]]
    centres = []
    for moment in FOLLOW_CHECK_MS:
        page.clock.fast_forward(moment - (FOLLOW_CHECK_MS[0] if centres else 0))
        centre, scale, (width, height) = view_centre(page)
        assert scale == pytest.approx(min(width, height) / scene["recorded"]["view_span_m"],
                                      rel=1e-4)
        half = ((width / 2 - 24) / scale, (height / 2 - 24) / scale)  # scene.js MARGIN_PX
        assert near_on_path(centre, robot, scene["bounds"], half) < 0.3
        centres.append(centre)
    # the car moved, and the view with it (by how much depends on the clip: a car slowing for
    # the ring moves under a metre in that time)
    assert math.dist(*centres) > 0.2


def stored_clicks(db_path: Path, public_token: str) -> list[tuple]:
    with closing(sqlite3.connect(db_path)) as db:
        return db.execute(
            "SELECT human_x, human_y, start_x, start_y, step, click_x, click_y FROM predictionrow "
            "JOIN participant ON participant.id = predictionrow.participant_id "
            "WHERE participant.session_token = ?", (public_token,)).fetchall()


def test_a_participant_walks_the_recorded_worlds_by_clicking(chromium, interaction_server,
                                                             interaction_study):
    config = yaml.safe_load(
        (interaction_study.configs_dir / f"{INTERACTION_STUDY}.yaml").read_text())
    context = chromium.new_context(viewport=VIEWPORT)
    context.clock.install()
    context.clock.pause_at(int(time.time() * 1000) + 1000)
    page = context.new_page()
    errors = []
    page.on("pageerror", lambda err: errors.append(str(err)))
    page.goto(f"{interaction_server.url}/s/{INTERACTION_STUDY}?{fresh_recruitment()}")
    consent_and_instructions(page)
    answered, parts = [], []
    screen = shown_screen(page)
    while screen != "survey":
        if screen == "trial":
            trial = current_state(page, INTERACTION_STUDY)["step"]
            if trial["is_practice"]:
                check_the_clip_follows_the_robot(page, trial)
            answered.append(answer_trial(page, INTERACTION_STUDY))
        else:
            if screen == "world":
                world = current_state(page, INTERACTION_STUDY)["step"]["world"]
                parts.append(world)
                assert page.inner_text("#world-title") == config["world_intros"][world]["title"]
                assert page.evaluate(ROAD_SHARE, "#world-canvas") > 0.05
            assert screen in ONWARD
            press_on(page, screen)
        screen = shown_screen(page)
    assert sorted(parts) == sorted(config["worlds"])
    answer_survey(page)
    visible(page, "done")
    token = page_token(page, INTERACTION_STUDY)
    assert errors == []
    context.close()

    per_part = config["practice_trials"] + config["trials_per_world"] + 1  # + attention check
    assert len(answered) == len(parts) * per_part
    assert [t["world"] for t in answered] == [w for w in parts for _ in range(per_part)]
    rows = stored_clicks(interaction_server.db_path, token)
    per_trial = config["start_states"] * config["steps_to_predict"]
    assert len(rows) == len(answered) * per_trial
    # every stored click is where the page clicked (mouse events carry whole CSS pixels)
    # a start is known by its robot and human positions: two trials may start the robot at the
    # same recorded state, never with the person at the same place too
    planned = {tuple(round(v, 3) for v in (*s["human"], *s["robot"])): (t, planned_path(t, s))
               for t in answered for s in t["start_states"]}
    for *where, step, click_x, click_y in rows:
        trial, path = planned[tuple(round(v, 3) for v in where)]
        error_px = math.dist(path[step], (click_x, click_y)) * trial["view"]["px_per_m"]
        assert error_px <= math.sqrt(2) + 1e-3


def at_first_trial(context, url: str):
    """A new participant's page (on a fake clock) at the first part's practice trial."""
    context.clock.install()
    page = context.new_page()
    page.goto(f"{url}/s/{INTERACTION_STUDY}?{fresh_recruitment()}")
    consent_and_instructions(page)
    press_on(page, shown_screen(page))  # the first part's introduction
    visible(page, "trial")
    return page


def test_the_prediction_screen_and_its_small_map_draw_the_recorded_road(chromium,
                                                                       interaction_server):
    context = chromium.new_context(viewport=VIEWPORT)
    page = at_first_trial(context, interaction_server.url)
    start_predicting(page)
    assert page.evaluate(ROAD_SHARE, "#trial-canvas") > 0.05
    assert page.evaluate(ROAD_SHARE, "#overview-canvas") > 0.02
    trial = current_state(page, INTERACTION_STUDY)["step"]
    drawn = robot_outline(page, trial)
    ratio = contrast(drawn["outline"], drawn["ground"])
    assert ratio >= 3, drawn  # on the road, under the reach disc's tint
    # the robot at its recorded width, times the view's outline_scale (app/prediction_view.py)
    view = trial["view"]
    assert 0 < view["outline_scale"] < 1
    width_px = trial["segment"]["sizes"][0][1] * view["outline_scale"] * view["px_per_m"]
    assert drawn["width"] == pytest.approx(max(width_px, 10), abs=3), (drawn, width_px)
    print(json.dumps({"robot outline on the recorded road under the reach tint": round(ratio, 2)}))
    context.close()


def test_reduced_motion_steps_through_a_recorded_clip_in_the_followed_view(
        chromium, interaction_server):
    context = chromium.new_context(viewport=VIEWPORT, reduced_motion="reduce")
    page = at_first_trial(context, interaction_server.url)
    page.clock.fast_forward(200)
    trial = current_state(page, INTERACTION_STUDY)["step"]
    scale = canvas_view(page)[0]
    width, height = view_centre(page)[2]
    context.close()
    # the same view as the animation's, moving a whole step at a time (not a still of the clip)
    assert scale == pytest.approx(min(width, height) / trial["scene"]["recorded"]["view_span_m"],
                                  rel=1e-4)


def test_the_driven_area_has_no_seams_and_each_line_its_style(chromium, interaction_server):
    page = chromium.new_page()
    page.goto(f"{interaction_server.url}/")
    out = page.evaluate(RECORDED_MAP)
    page.close()
    palette = out["palette"]
    road, field = hex_rgb(palette["road"]), hex_rgb(palette["field"])
    assert out["field"] == field
    assert len(out["block"]) > 30000 and all(px == road for px in out["block"])

    def width(name: str) -> int:  # pixels across the line that are not the field
        return sum(px != field for px in out["lines"][name]["across"])

    def painted(name: str) -> float:  # share of pixels along the line that are not the field
        along = out["lines"][name]["along"]
        return sum(px != field for px in along) / len(along)

    def darkest(name: str) -> list[int]:
        return min(out["lines"][name]["across"] + out["lines"][name]["along"], key=sum)

    assert width("stop") > width("kerb") > width("border") >= 1
    assert painted("kerb") == painted("border") == painted("stop") == 1
    assert painted("dashed") == pytest.approx(5 / 17.5, abs=0.03)  # 3 m painted, 9 m gap
    assert painted("virtual") == 0  # an unpainted lanelet border (an old bank's) is not drawn
    assert darkest("kerb") == hex_rgb(palette["kerb"])
    assert darkest("stop") == hex_rgb(palette["stop"])
    # a border line is thinner than a pixel row's full cover: its darkest pixel only tends
    # to the palette colour
    assert sum(darkest("border")) < sum(field)


# what a participant of the recorded-traffic study must never read (another world's nouns)
ROBOT_WORDS = re.compile(r"\b(robots?|persons?|humans?|goals?|obstacles?)\b", re.I)


def test_the_instructions_legend_and_prompt_read_cars(chromium, interaction_server):
    from playwright.sync_api import expect

    context = chromium.new_context(viewport=VIEWPORT)
    context.clock.install()
    page = context.new_page()
    page.goto(f"{interaction_server.url}/s/{INTERACTION_STUDY}?{fresh_recruitment()}")
    visible(page, "consent")
    page.check("#consent-check")
    page.click("#consent-agree")
    visible(page, "instructions")
    expect(page.locator("#demo-caption")).to_contain_text("the blue car (B) and the orange car (O)")
    page.clock.run_for(6500)  # the demo predicts from the blue car's own start
    expect(page.locator("#demo-caption")).to_contain_text("Click where the blue car will be")
    expect(page.locator("#demo-canvas")).to_have_attribute(
        "aria-label", "Demonstration clip of the blue car and the orange car moving")
    instructions = page.inner_text("#screen-instructions")
    assert "B the blue car (solid)" in " ".join(instructions.split())
    assert ROBOT_WORDS.findall(instructions) == []
    page.click("#instructions-done")
    press_on(page, shown_screen(page))  # the first part's introduction
    visible(page, "trial")
    start_predicting(page)
    expect(page.locator("#trial-message")).to_have_text(
        "Click where the blue car will be after each of the next 3 steps.")
    legend = " ".join(page.inner_text("#screen-trial .legend").split())
    assert legend.startswith("B blue car O orange car"), legend
    assert ROBOT_WORDS.findall(page.inner_text("#screen-trial")) == []
    context.close()
