"""A study's completion codes: generated at random and kept in the data dir, or the config's.

A code in a public repository is a code anyone can paste into the platform, so a study with
`recruitment.codes: generated` gets one random code per ending the first time it is served
(or `tomstudy codes` asks). They live in <data dir>/studies/<study>/completion_codes.json,
readable by the server's user only, and survive restarts. Several workers starting at once
agree on one set: each writes its candidate to a temporary file and hard-links it to the
final name, which fails for all but the first; the others read what the first wrote.

Production refuses a pinned code that appears in the repository's own study configs
(`refuse_public_codes`): those are the paper's example codes, known to everyone.
"""

import json
import os
import secrets
import tempfile
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path

import yaml

from app.layout import Layout
from app.settings import REPO_ROOT
from app.study.config import ENDING_NAMES, StudyConfig

OUTCOMES = ("completed", *ENDING_NAMES)
# no 0/O, 1/I/L or U: a participant may have to type the code
ALPHABET = "ABCDEFGHJKMNPQRSTVWXYZ23456789"
CODE_CHARS = 10  # 30**10: about 49 bits
PUBLIC_CONFIGS = REPO_ROOT / "study_configs"
# what Prolific should do with each ending's submissions (docs/run/go-live.md, "Endings")
PROLIFIC_ACTIONS = {
    "completed": "approve and pay",
    "failed_checks": "manually review",
    "excluded": "manually review",
    "declined_consent": "request a return",
    "screened_out": "request a return (or a screen-out payment)",
}


class PublicCode(ValueError):
    """A production study pins a completion code that is public in the repository."""


def new_code() -> str:
    """A random completion code of CODE_CHARS characters from ALPHABET."""
    return "".join(secrets.choice(ALPHABET) for _ in range(CODE_CHARS))


def new_codes() -> dict[str, str]:
    """One distinct random code per outcome."""
    codes: dict[str, str] = {}
    while len(set(codes.values())) < len(OUTCOMES):
        codes = {outcome: new_code() for outcome in OUTCOMES}
    return codes


def study_codes(layout: Layout, study_id: str) -> dict[str, str]:
    """The study's generated codes (outcome -> code), made and kept on first use."""
    path = layout.completion_codes(study_id)
    if not path.is_file():
        _create_once(path, {"study_id": study_id, "created_at": datetime.now(UTC).isoformat(),
                            "codes": new_codes()})
    codes = json.loads(path.read_text())["codes"]
    missing = [o for o in OUTCOMES if not codes.get(o)]
    if missing:
        raise ValueError(f"{path}: no code for {', '.join(missing)}; delete the file only if "
                         "no participant was given a code from it")
    return {outcome: codes[outcome] for outcome in OUTCOMES}


def _create_once(path: Path, data: dict) -> None:
    """Write `data` to `path` unless another process did first (then keep theirs)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".codes-")  # mode 0600
    try:
        with os.fdopen(fd, "w") as out:
            json.dump(data, out, indent=2)
            out.flush()
            os.fsync(out.fileno())
        os.link(tmp, path)  # atomic, and refuses to replace a file another worker made
    except FileExistsError:
        pass
    finally:
        os.unlink(tmp)


def served_config(config: StudyConfig, layout: Layout, study_id: str) -> StudyConfig:
    """`config` with the codes its participants are given: generated ones filled in."""
    if config.recruitment.codes == "pinned":
        return config
    recruitment = config.recruitment.with_codes(study_codes(layout, study_id))
    return config.model_copy(update={"recruitment": recruitment})


def codes_table(config: StudyConfig) -> list[dict]:
    """Each ending's code and what to do with it on Prolific, for the researcher."""
    return [{"ending": outcome, "completion_code": config.recruitment.ending(outcome)
             .completion_code, "prolific_action": PROLIFIC_ACTIONS[outcome]}
            for outcome in OUTCOMES]


def refuse_public_codes(config: StudyConfig, study_id: str,
                        public_dir: Path = PUBLIC_CONFIGS) -> None:
    """PublicCode naming the field if `config` pins a code found in the repository's configs."""
    public = dict(public_codes(public_dir))
    for field, code in config.recruitment.pinned_codes().items():
        if code in public:
            raise PublicCode(
                f"{study_id}: {field}: {code!r} is public (in the repository's "
                f"{public[code]}); leave the codes out (`recruitment.codes: generated`) or "
                f"use your platform's own; refusing to start")


def public_codes(public_dir: Path) -> Iterator[tuple[str, str]]:
    """(code, file) for every completion_code written in a YAML file under `public_dir`."""
    for path in sorted(Path(public_dir).rglob("*.yaml")):
        try:
            data = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError):
            continue
        for code in _codes_in(data):
            yield code, str(path.relative_to(public_dir.parent))


def _codes_in(node) -> Iterator[str]:
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "completion_code" and isinstance(value, str) and value:
                yield value
            else:
                yield from _codes_in(value)
    elif isinstance(node, list):
        for item in node:
            yield from _codes_in(item)
