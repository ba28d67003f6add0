"""`tomstudy prereg`: the preregistration holds the frozen bundle's hashes, the analysis plan's
numbers and the exclusion rules as the study's files have them, names what it cannot know, and
is one self-contained HTML page."""

import json
import re
import shutil

import pytest
import yaml
from typer.testing import CliRunner

from app.cli import cli
from app.prereg.document import Table
from app.prereg.inputs import DEPARTURES
from app.prereg.readme import readme_table
from app.prereg.sections import DEVIATIONS_HEADING, MEASURED_COLUMNS
from app.prereg.write import write_prereg
from app.settings import Settings, get_settings
from tests.conftest import INTERACTION_STUDY, REPO

PAPER = "paper_study"
MANIFEST = REPO / "study_configs" / "bundles" / PAPER / "manifest.json"


@pytest.fixture(scope="module")
def paper(tmp_path_factory) -> dict[str, str]:
    """The paper study's preregistration with an empty data dir: no instrument, no power."""
    out = tmp_path_factory.mktemp("prereg")
    settings = Settings(data_dir=out / "var", configs_dir=REPO / "study_configs")
    md, html = write_prereg(settings, PAPER, out / "prereg")
    return {"md": md.read_text(), "html": html.read_text()}


def test_the_bundles_bank_config_and_checkpoint_hashes_are_the_manifests(paper):
    manifest = json.loads(MANIFEST.read_text())
    configs = {name: entry["sha256"] for name, entry in manifest["files"].items()
               if name.startswith("configs/")}
    assert len(configs) == 6
    assert "| trial bank SHA-256 (its JSON; every export row's bank_sha256) | " \
           f"{manifest['bank_sha256']} |" in paper["md"]
    for text in paper.values():
        assert manifest["bank_sha256"] in text and manifest["content_sha256"] in text
        assert manifest["files"]["bank.json.gz"]["sha256"] in text
        for name, sha in configs.items():
            assert f"{name} SHA-256" in text and sha in text
        for models in manifest["models"].values():
            for seeds in models.values():
                assert all(content in text for content in seeds.values())


def test_alpha_and_the_smallest_effect_of_interest_with_their_sources(paper):
    md = paper["md"]
    assert "alpha = 0.01 for every test" in md
    assert "smallest effect of interest (SESOI) of the equivalence test is 0.005" in md
    assert re.search(r"\| alpha of every Ours-vs-VAE test \| 0\.01 \| analysis/stats\.py \| "
                     r"ALPHA \| [0-9a-f]{64} \|", md)
    assert re.search(r"\| smallest effect of interest \| 0\.005 \| study_configs/paper_study"
                     r"\.yaml \| smallest_effect_of_interest \| [0-9a-f]{64} \|", md)
    assert "| primary: Ours vs the VAE |" in md and "| two-sided | 0.01 |" in md


def test_the_paper_studys_exclusion_rules_in_words(paper):
    rules = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())["exclusions"]
    assert rules == {"failed_attention_check": True, "incomplete": True,
                     "too_fast_trial_ms": 4000, "too_fast_max_fraction": 0.25}
    md = paper["md"]
    assert "- A participant who fails an attention check is excluded. A check passes when at " \
           "least 4 of the 5 first clicks point within 45 degrees" in md
    assert "- A participant who did not complete the study is excluded." in md
    assert "- A participant is excluded when more than 25% of their scored trials were " \
           "answered within 4 s of being shown" in md


def test_the_paper_studys_worlds_design_and_sample(paper):
    md = paper["md"]
    assert "| highway | simulated | confirmatory (unchecked) |" in md
    assert "| obstacle | simulated | exploratory | No clip separates the hypotheses" in md
    assert "Planned sample: **30 participants** recruited on prolific" in md
    assert "| highway | 60 | discriminability 30, random 30 | 1 | 1 |" in md
    assert "Worlds that test H: highway. Exploratory worlds (obstacle)" in md
    assert "| participants | 22 from two universities |" in md  # docs/reproduce/departures.md


def test_missing_instrument_and_power_are_named_with_their_commands(paper):
    md = paper["md"]
    assert "## Inputs not available" in md
    assert "`tomstudy instrument --study paper_study` has not run" in md
    for kind in ("coarse", "coarse_scene", "coarse_momentum"):
        assert f"`tomstudy power --study paper_study --kind {kind}`" in md
    assert "The design goal (would the primary test confirm the hypothesis at this design?) " \
           "is not available: run `tomstudy instrument --study paper_study`." in md
    assert "instrument check pass rate" not in md.split("## Sources")[1]  # nothing invented


def test_every_cited_number_has_a_file_and_its_hash(paper):
    sources = paper["md"].split("## Sources")[1]
    rows = [line for line in sources.splitlines() if line.startswith("| ")][1:]
    assert len(rows) > 40
    for row in rows:
        assert re.search(r"\| [0-9a-f]{64} \|$", row), row
    assert "| planned participants | 30 | study_configs/paper_study.yaml | target_sample_size |" \
        in sources


def test_the_html_page_is_self_contained_and_has_every_section(paper):
    html = paper["html"]
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", html)
    assert not re.search(r"<(link|script|iframe|object)\b", html)
    assert "@import" not in html and "url(" not in html
    titles = re.findall(r"^## (.+)$", paper["md"], re.MULTILINE)
    assert titles[:3] == ["Study information and hypotheses", "Inputs not available", "Design"]
    assert titles[-3:] == ["Observer family", "Deviations from the paper", "Sources"]
    for title in titles:
        assert f">{title}</h2>" in html
    assert "<code>tomstudy instrument --study paper_study</code>" in html


def test_measured_columns_are_export_columns_described_by_the_codebook():
    from app.core.contracts import EXPORT_COLUMNS, plugin_columns
    from app.prereg.sections import measured_rows

    known = {*EXPORT_COLUMNS, *(c for name in ("coarse", "coarse_scene", "coarse_momentum")
                               for c in plugin_columns(name))}
    assert set(MEASURED_COLUMNS) <= known
    rows = dict((name, (unit, text)) for name, unit, text in measured_rows())
    assert rows["participant_vx"][0] == "m/s" and rows["click_time_ms"][0] == "ms"
    assert "coarse observer coarse_scene" in rows["coarse_scene_vx"][1]


def test_the_departures_table_is_read_by_its_heading():
    table = readme_table(DEPARTURES.read_text(), DEVIATIONS_HEADING)
    assert isinstance(table, Table)
    assert table.header == ("departure", "the paper", "here", "why", "checked by")
    assert {row[0] for row in table.rows} >= {"Obstacle data", "participants", "analysis"}
    with pytest.raises(ValueError, match="no heading"):
        readme_table("# x\n", DEVIATIONS_HEADING)


# -- a built study: the interaction study's pipeline, with instrument results beside it


def goal_result(bank: str, worlds: list[str], met: bool) -> dict:
    """goal.json as `tomstudy instrument` writes it (app/observers/design_goal.py), trimmed."""
    rows = [{"arm": "all", "bank_trials": 5, "p_ours": 0.0, "p_vae": 0.5, "participants": 22,
             "participants_only_power": 0.0, "seeds": "family", "trials_each": 3,
             "variant": variant, "world": world}
            for world in worlds for variant in ("coarse", "coarse_scene", "coarse_momentum",
                                                "precise", "constant_velocity")]
    return {"alpha": 0.01, "bank_sha256": bank, "goal_power": 0.8, "reps": 400,
            "design": {"bank_trials": 5, "participants": 22, "trials_each": 3},
            "goal_met": {w: met for w in worlds},
            "needed": [{"bank_trials": 5, "participants_needed": None, "trials_each": 3,
                        "world": w} for w in worlds],
            "rows": rows}


def instrument_result(bank: str, worlds: list[str]) -> dict:
    """instrument.json as app/observers/simulated_study.py writes it, trimmed."""
    return {"alpha": 0.01, "bank_sha256": bank, "n_per_population": 22, "replications": 50,
            "pass_rate": {w: 0.0 for w in worlds}, "passed": {w: False for w in worlds}}


@pytest.fixture
def built(interaction_study, tmp_path):
    """The interaction study's bundle linked into a fresh data dir, its configs copied without
    exploratory worlds (they do not shape the bank): (settings, bank hash, worlds)."""
    configs = tmp_path / "configs"
    shutil.copytree(interaction_study.configs_dir, configs)
    path = configs / f"{INTERACTION_STUDY}.yaml"
    study = yaml.safe_load(path.read_text())
    study.pop("exploratory_worlds")
    path.write_text(yaml.safe_dump(study))
    settings = Settings(data_dir=tmp_path / "var", configs_dir=configs)
    bundle = settings.layout.bundle_dir(INTERACTION_STUDY)
    bundle.parent.mkdir(parents=True)
    bundle.symlink_to(interaction_study.layout.bundle_dir(INTERACTION_STUDY))
    manifest = json.loads((bundle / "manifest.json").read_text())
    return settings, manifest["bank_sha256"], study["worlds"]


def write_instrument(settings: Settings, bank: str, worlds: list[str], met: bool) -> None:
    """Put instrument.json and goal.json where `tomstudy instrument` writes them."""
    out = settings.layout.instrument_report(INTERACTION_STUDY)
    out.mkdir(parents=True)
    (out / "goal.json").write_text(json.dumps(goal_result(bank, worlds, met)))
    (out / "instrument.json").write_text(json.dumps(instrument_result(bank, worlds)))


def test_a_world_the_instrument_finds_missing_the_goal_is_named_exploratory(built, tmp_path):
    settings, bank, worlds = built
    write_instrument(settings, bank, worlds, met=False)
    md = write_prereg(settings, INTERACTION_STUDY, tmp_path / "out")[0].read_text()
    for world in worlds:
        assert f"| {world} | recorded | exploratory | the instrument's design goal is missed " \
               "here (goal.json goal_met false), yet the study config does not mark it" in md
    assert "Worlds that test H: none. Exploratory worlds (roundabout, intersection)" in md
    assert "`tomstudy instrument --study interaction_study` has not run" not in md
    assert re.search(r"\| design goal met in roundabout \| no \| \S+/reports/instrument-"
                     r"interaction_study/goal\.json \| goal_met\.roundabout \|", md)
    assert "| roundabout | none up to the search's largest sample |" in md


def test_a_met_goal_makes_a_world_confirmatory(built, tmp_path):
    settings, bank, worlds = built
    write_instrument(settings, bank, worlds, met=True)
    md = write_prereg(settings, INTERACTION_STUDY, tmp_path / "out")[0].read_text()
    assert f"| {worlds[0]} | recorded | confirmatory | a test of the hypothesis" in md
    assert "| roundabout | family | coarse | 0 | 0.5 |" in md


def test_an_instrument_result_of_another_bank_is_not_used(built, tmp_path):
    settings, bank, worlds = built
    write_instrument(settings, "f" * 64, worlds, met=True)
    md = write_prereg(settings, INTERACTION_STUDY, tmp_path / "out")[0].read_text()
    assert f"ran on bank ffffffffffff, not the bundle's {bank[:12]}: rerun `tomstudy " \
           "instrument --study interaction_study`" in md
    assert "| confirmatory (unchecked) |" in md


# -- the command line


def invoke(monkeypatch, data_dir, configs_dir, *args):
    """Run `tomstudy prereg ARGS` with the settings' dirs set."""
    monkeypatch.setenv("TOMSTUDY_DATA_DIR", str(data_dir))
    monkeypatch.setenv("TOMSTUDY_CONFIGS_DIR", str(configs_dir))
    get_settings.cache_clear()
    try:
        return CliRunner().invoke(cli, ["prereg", *args])
    finally:
        get_settings.cache_clear()


def test_an_unknown_study_is_an_error_naming_study(monkeypatch, tmp_path):
    result = invoke(monkeypatch, tmp_path, REPO / "study_configs", "--study", "no_such_study")
    assert result.exit_code == 2
    assert result.output.startswith("error: --study: no_such_study: ")
    assert result.output.count("\n") == 1


def test_a_study_without_its_bundle_is_an_error_naming_study(monkeypatch, tmp_path):
    configs = tmp_path / "configs"
    shutil.copytree(REPO / "study_configs", configs, ignore=shutil.ignore_patterns("bundles"))
    result = invoke(monkeypatch, tmp_path / "var", configs, "--study", PAPER)
    assert result.exit_code == 2
    assert result.output.startswith("error: --study: paper_study: ")
    assert "no bundle of study paper_study" in result.output


def test_the_command_writes_both_files(monkeypatch, tmp_path):
    result = invoke(monkeypatch, tmp_path, REPO / "study_configs", "--study", PAPER)
    assert result.exit_code == 0, result.output
    out = tmp_path / "reports" / "prereg-paper_study"
    assert result.output.splitlines() == [f"wrote {out / 'preregistration.md'}",
                                          f"wrote {out / 'preregistration.html'}"]
