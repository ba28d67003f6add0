"""The codebook covers every export column of the contracts, and nothing else."""

import hashlib

import pytest

from analysis.codebook import (
    CODEBOOK,
    FIELD_TYPES,
    PLUGIN_COLUMNS,
    StudyTerms,
    data_package,
    table_schema,
)
from app.core.contracts import (
    COARSE_OBSERVERS,
    EXPORT_COLUMNS,
    PLUGIN_FIELDS,
    SCHEMAS,
    STUDY_VERSION,
    WHAT,
    plugin_columns,
)

CONTRACTS = {"predictions": EXPORT_COLUMNS, **{what: tuple(s) for what, s in SCHEMAS.items()}}


def test_every_contract_column_has_an_entry_and_every_entry_a_column():
    assert set(CODEBOOK) == set(WHAT)
    for what, columns in CONTRACTS.items():
        assert set(columns) - set(CODEBOOK[what]) == set(), f"{what}: columns without an entry"
        assert set(CODEBOOK[what]) - set(columns) == set(), f"{what}: entries of no column"
    assert set(PLUGIN_COLUMNS) == set(PLUGIN_FIELDS)
    for what, entries in CODEBOOK.items():
        for name, entry in entries.items():
            assert entry.text.endswith("."), (what, name)


def test_each_field_has_its_contract_type_and_order():
    for what, columns in CONTRACTS.items():
        fields = table_schema(what, columns)["fields"]
        assert [f["name"] for f in fields] == list(columns)
        assert {f["type"] for f in fields} <= set(FIELD_TYPES.values())
    kinds = {f["name"]: f["type"] for f in table_schema("survey", CONTRACTS["survey"])["fields"]}
    assert kinds["answered_at"] == "datetime" and kinds["export_version"] == "integer"


def test_plugin_and_observer_columns_are_described_from_plugin_fields():
    columns = [*EXPORT_COLUMNS, *plugin_columns(COARSE_OBSERVERS[0]), *plugin_columns("ctrv")]
    fields = {f["name"]: f for f in table_schema("predictions", columns)["fields"]}
    assert "plug-in predictor ctrv" in fields["ctrv_vx"]["description"]
    assert fields["ctrv_vx"]["unit"] == "m/s" and fields["ctrv_code"]["type"] == "integer"
    assert fields["ctrv_sha256"]["constraints"]["pattern"] == "[0-9a-f]{64}"
    assert "coarse observer" in fields[f"{COARSE_OBSERVERS[0]}_vy"]["description"]


def test_a_column_outside_the_contract_is_refused_by_name():
    with pytest.raises(ValueError, match="columns: favourite_colour not in the survey"):
        table_schema("survey", [*CONTRACTS["survey"], "favourite_colour"])
    with pytest.raises(ValueError, match="what: unknown export 'clicks'"):
        table_schema("clicks", [])


def test_the_study_closes_worlds_questions_and_world_orders():
    terms = StudyTerms(worlds=("highway", "obstacle"), questions=("difficulty", "strategy"))
    survey = {f["name"]: f for f in table_schema("survey", CONTRACTS["survey"], terms)["fields"]}
    assert survey["question"]["constraints"]["enum"] == ["difficulty", "strategy"]
    sheet = {f["name"]: f for f in table_schema("participants", CONTRACTS["participants"],
                                                 terms)["fields"]}
    one_world = "(highway|obstacle)"
    assert sheet["world_order"]["constraints"]["pattern"] == f"{one_world}(,{one_world})*"
    predictions = {f["name"]: f for f in table_schema("predictions", EXPORT_COLUMNS,
                                                       terms)["fields"]}
    assert predictions["world"]["constraints"]["enum"] == ["highway", "obstacle"]


def test_the_package_carries_the_file_version_and_hashes():
    csv = b"export_version,study_id\n2,s\n"
    hashes = {key: ["a"] for key in STUDY_VERSION}
    package = data_package("survey", CONTRACTS["survey"], csv, "s_survey.csv", 1, "my_study",
                           hashes)
    resource = package["resources"][0]
    assert resource["hash"] == "sha256:" + hashlib.sha256(csv).hexdigest()
    assert (resource["bytes"], resource["rows"], resource["path"]) == (len(csv), 1,
                                                                      "s_survey.csv")
    assert package["name"] == "my-study-survey" and package["export_version"] == 2
    assert package["study_hashes"] == hashes
    with pytest.raises(ValueError, match="hashes: missing models_sha256"):
        data_package("survey", CONTRACTS["survey"], csv, "s.csv", 1, "s",
                     {"config_sha256": [], "bank_sha256": []})
