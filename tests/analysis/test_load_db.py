"""Reading the server's database gives exactly the DataFrame of its CSV export."""

import io

import pandas as pd
from sqlalchemy import insert
from sqlmodel import Session

from analysis.load import load_csv, load_database
from app.core.contracts import STORED_NAMES
from app.core.csvsafe import write_csv
from app.researcher.exports import predictions_frame
from app.server.storage.db import create_tables, make_engine
from app.server.storage.tables import Participant, PredictionRow, TrialResponse
from tests.analysis.fixed_data import fixed_predictions


def _store(engine, frame: pd.DataFrame) -> None:
    """Write the fixed rows into the server's tables (as crud.py would have)."""
    skip = ("id", "plugins")  # plugins: the column's default, {} (a study without plug-ins)
    pred_cols = [c.name for c in PredictionRow.__table__.columns if c.name not in skip]
    with engine.begin() as conn:
        for n, (pid, rows) in enumerate(frame.groupby("participant_id", sort=True)):
            first = rows.iloc[0]
            ident = conn.execute(insert(Participant.__table__).values(
                study_id="paper_study", recruitment=first["recruitment"],
                external_id=f"ext{n}", session_token=f"tok{n}", public_id=pid,
                recruitment_params={}, client={}, world_order="highway,obstacle", plan=[],
                position=0, completed=bool(n != 1), attention_failed=int(n == 2),
                outcome="completed" if n != 1 else None, config_sha256=first["config_sha256"],
                bank_sha256=first["bank_sha256"],
            )).inserted_primary_key[0]
            for _, trial in rows.groupby("submission_id", sort=False):
                t = trial.iloc[0]
                conn.execute(insert(TrialResponse.__table__).values(
                    submission_id=t["submission_id"], participant_id=ident,
                    trial_id=t["trial_id"], world=t["world"],
                    world_position=int(t["world_position"]),
                    trial_index=int(t["trial_index"]), is_practice=False, attention_check=False,
                    shown_at_ms=0.0, submitted_at_ms=9000.0, duration_ms=9000.0,
                    client_duration_ms=9000.0, server_duration_ms=9500.0, replays=1,
                    clip_sha256=t["clip_sha256"]))
                stored = trial.assign(participant_id=ident).rename(columns=STORED_NAMES)
                values = stored[pred_cols].to_dict("records")
                conn.execute(insert(PredictionRow.__table__), values)


def test_database_and_csv_export_load_identically(tmp_path):
    url = f"sqlite:///{tmp_path / 'study.db'}"
    engine = make_engine(url)
    create_tables(engine)
    _store(engine, fixed_predictions())
    with Session(engine) as db:
        text = export_csv(db, "paper_study")
    engine.dispose()
    from_csv = load_csv(io.StringIO(text))
    from_db = load_database(url, "paper_study")
    assert len(from_db) == len(fixed_predictions()) == len(from_csv)
    pd.testing.assert_frame_equal(from_db, from_csv)
    assert from_db["completed"].sum() < len(from_db) and (~from_db["attention_passed"]).any()
    assert set(from_db["start_kind"]) == {"own", "same_lane", "near"}


def export_csv(db: Session, study_id: str) -> str:
    """The predictions export as the server writes it."""
    buffer = io.StringIO()
    write_csv(predictions_frame(db, study_id), buffer)
    return buffer.getvalue()


def test_formula_text_exports_as_text_and_loads_as_stored(tmp_path):
    url = f"sqlite:///{tmp_path / 'study.db'}"
    engine = make_engine(url)
    create_tables(engine)
    frame = fixed_predictions()
    ids = {"p00": '=HYPERLINK("http://x","y")', "p01": "@SUM(1+1)", "p02": "-2+3",
           "p03": "'quoted"}
    frame["clip_sha256"] = frame["participant_id"].map(ids)
    frame["cv_vx"] = -1.5
    _store(engine, frame)
    with Session(engine) as db:
        text = export_csv(db, "paper_study")
    engine.dispose()
    raw = pd.read_csv(io.StringIO(text))
    assert sorted(set(raw["clip_sha256"])) == [
        "''quoted", "'-2+3", "'=HYPERLINK(\"http://x\",\"y\")", "'@SUM(1+1)"]
    assert raw["cv_vx"].dtype == float and (raw["cv_vx"] == -1.5).all()
    assert ",-1.5," in text and "\"-1.5\"" not in text
    from_csv = load_csv(io.StringIO(text))
    pd.testing.assert_frame_equal(from_csv, load_database(url, "paper_study"))
    assert set(from_csv["clip_sha256"]) == set(ids.values())
    assert "external_id" not in raw.columns
