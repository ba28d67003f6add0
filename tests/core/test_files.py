"""write_json, the one JSON writer of analysis and app: sorted keys, numpy and paths as plain
values, and an old file left whole when a write fails."""

import json
from pathlib import Path

import numpy as np
import pytest

from app.core.files import write_json


def test_write_json_gives_equal_bytes_for_equal_data_and_plain_numpy_values(tmp_path):
    data = {"b": np.float64(0.25), "a": np.arange(3), "n": np.int64(7),
            "path": Path("out") / "x.png", "ok": np.bool_(True)}
    write_json(tmp_path / "one" / "x.json", data)
    write_json(tmp_path / "two.json", dict(reversed(data.items())))
    text = (tmp_path / "one" / "x.json").read_text()
    assert text == (tmp_path / "two.json").read_text() and text.endswith("}\n")
    assert list(json.loads(text)) == ["a", "b", "n", "ok", "path"]
    assert json.loads(text) == {"a": [0, 1, 2], "b": 0.25, "n": 7, "ok": True,
                                "path": "out/x.png"}


def test_write_json_that_fails_keeps_the_old_file(tmp_path):
    target = tmp_path / "summary.json"
    write_json(target, {"kept": 1})
    with pytest.raises(TypeError, match="not JSON-serialisable: object"):
        write_json(target, {"bad": object()})
    assert json.loads(target.read_text()) == {"kept": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]
