"""`tomstudy serve` run to its preflight, as the hosting and rate-limit tests run it to see a
refusal (which must come before the server serves)."""

import subprocess

from tests.conftest import REPO, TOMSTUDY, free_port, patience


def run_serve(small_study, tmp_path, *args: str, **env: str) -> subprocess.CompletedProcess:
    """`tomstudy serve ARGS` on a fresh database; a refusal must come before it serves."""
    environment = small_study.env(f"sqlite:///{tmp_path / 'serve.db'}", **env)
    return subprocess.run([TOMSTUDY, "serve", "--port", str(free_port()), "--study",
                           small_study.study_id, *args], env=environment, cwd=REPO,
                          capture_output=True, text=True, timeout=patience(60))
