"""Fixtures of the analysis tests."""

import gzip

import pytest

from app.core.contracts import StudyInputs
from tests.analysis.report_inputs import BANK_JSON, MODELS, RULES


@pytest.fixture
def inputs(tmp_path) -> StudyInputs:
    """The study's side of an analysis: a bundle's gzipped bank with 3 seeds per model."""
    bank = tmp_path / "bundles" / "paper_study" / "bank.json.gz"
    bank.parent.mkdir(parents=True)
    bank.write_bytes(gzip.compress(BANK_JSON))
    config = {"exclusions": RULES.model_dump(), "bundle": "shipped"}
    return StudyInputs(config=config, rules=RULES, bank=bank, models=MODELS)
