"""Fixtures of the study API tests: each backend's fresh database, the app, the bank."""

import itertools
import json

import pytest

from app.layout import Layout
from tests.conftest import fresh_database
from tests.study.flow import make_client

_db_counter = itertools.count()


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def db_url(request, tmp_path):
    """A fresh empty database of each backend."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'study.db'}"
    return fresh_database(request.getfixturevalue("postgres_url"), f"api{next(_db_counter)}")


@pytest.fixture(scope="session")
def served_study(small_study):
    """The study `client` serves and `bank` reads (a test module may serve another)."""
    return small_study


@pytest.fixture
def client(served_study, db_url):
    """The app on a fresh database."""
    with make_client(served_study, db_url) as c:
        yield c


@pytest.fixture
def codes(client, served_study) -> dict[str, str]:
    """Each outcome's completion code as `client`'s app gives it (the study's generated ones)."""
    from app.server.completion_codes import OUTCOMES

    recruitment = client.app.state.studies[served_study.study_id].config.recruitment
    return {outcome: recruitment.ending(outcome).completion_code for outcome in OUTCOMES}


@pytest.fixture(scope="module")
def bank(served_study) -> dict:
    """Bank trials by id (the test reads the true moves for attention checks)."""
    raw = json.loads(Layout(served_study.data_dir).bank(served_study.study_id).read_text())
    return {t["trial_id"]: t for w in raw["worlds"].values() for t in w["trials"]}
