"""CSV cells a spreadsheet would run as formulas are written as text; numbers stay numbers."""

import io

import pandas as pd
import pytest

from app.core.csvsafe import restore_cell, restore_text, safe_cell, write_csv

FORMULAS = ['=HYPERLINK("http://x","y")', "+1+2", "-2+3", "@SUM(A1:A9)", "\t=1", "\r=1"]


@pytest.mark.parametrize("text", FORMULAS)
def test_a_formula_start_gets_a_quote_and_comes_back(text):
    assert safe_cell(text) == "'" + text
    assert restore_cell(safe_cell(text)) == text


@pytest.mark.parametrize("text", ["alice", "", "5f3a9c", "2026-01-01T00:00:00+00:00", "a=b"])
def test_plain_text_is_unchanged(text):
    assert safe_cell(text) == text == restore_cell(text)


@pytest.mark.parametrize("text", ["'", "'plain", "'=1", "''=1"])
def test_text_starting_with_a_quote_survives_the_round_trip(text):
    assert restore_cell(safe_cell(text)) == text


def test_csv_keeps_numbers_and_neutralises_text():
    frame = pd.DataFrame({"external_id": ['=HYPERLINK("http://x","y")', "bob", None],
                          "answer": ["@SUM(1,2)", "-", "fine"],
                          "vx": [-1.5, 0.25, -3e-7], "code": [-1, 0, 2],
                          "completed": [True, False, True]})
    buffer = io.StringIO()
    write_csv(frame, buffer)
    lines = buffer.getvalue().splitlines()
    assert lines[1] == """"'=HYPERLINK(""http://x"",""y"")","'@SUM(1,2)",-1.5,-1,True"""
    assert lines[2] == "bob,'-,0.25,0,False"
    back = pd.read_csv(io.StringIO(buffer.getvalue()))
    assert back["vx"].dtype == float and back["vx"].tolist() == [-1.5, 0.25, -3e-7]
    assert back["code"].dtype.kind == "i" and back["completed"].dtype == bool
    assert back["external_id"][0] == "'=HYPERLINK(\"http://x\",\"y\")"
    restored = restore_text(back, ["external_id", "answer"])
    assert restored["answer"].tolist() == frame["answer"].tolist()
    assert restored["external_id"].tolist()[:2] == frame["external_id"].tolist()[:2]
