"""Process-wide settings, read once from the environment (prefix TOMSTUDY_)."""

import ipaddress
from functools import lru_cache
from pathlib import Path

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict
from sqlalchemy.engine import make_url

from app.layout import DEFAULT_DATA_DIR, Layout

REPO_ROOT = Path(__file__).resolve().parent.parent
# Host names every server answers to: what this machine, its healthcheck and a proxy on
# it use. Any other Host (a DNS-rebinding page's name) is refused unless configured.
LOOPBACK_HOSTS = ("localhost", "127.0.0.1", "::1", "[::1]")


class Settings(BaseSettings):
    """Where data lives, which database to use and how researchers authenticate."""

    model_config = SettingsConfigDict(env_prefix="TOMSTUDY_", extra="ignore")

    # where everything generated lives (simulated data, models, built bundles, the SQLite database);
    # default var/ in the repository
    data_dir: Path = Field(default=DEFAULT_DATA_DIR)
    # the folder of study configs the commands and the server read (study_configs/ in the
    # repository)
    configs_dir: Path = Field(default=REPO_ROOT / "study_configs")
    # a lab's recordings (recorded worlds' sources); default <data dir>/recordings
    recordings_dir: Path | None = None
    # the study database's SQLAlchemy URL (DATABASE_URL, e.g. postgresql+psycopg://...); '' = SQLite
    # under the data dir
    database_url: str = Field(default="", validation_alias="DATABASE_URL")
    # no default anywhere: `serve` generates one when unset (app/main.py)
    admin_token: str = ""
    # secrets as files (compose secrets, /run/secrets/...): read when set
    admin_token_file: Path | None = None
    # a file holding the database password, set into DATABASE_URL when present
    database_password_file: Path | None = None
    # comma-separated public host names of the study (e.g. study.example.org)
    allowed_hosts: str = ""
    # where the rate limits and the researcher lockout count (app/http/limitstore.py): a
    # `limits` storage URI. memory:// counts in each worker process (one worker: SQLite);
    # redis://host:6379/0 shares the counts between every worker and host
    rate_limit_storage: str = "memory://"
    # per client (per worker with memory://); "" turns a limit off (refused in production).
    # Session starts per client address: a classroom of 30 behind one NAT starts at once,
    # reloads included
    rate_limit_starts: str = "60/minute"
    # requests of one started session (/api/session/...), per session token: a participant's
    # page makes under half of it, leaving room for its retries (docs/run/hosting.md; counted by
    # tests/e2e/test_page_requests_browser.py -s)
    rate_limit_requests: str = "120/minute"
    # comma-separated addresses or networks of the reverse proxy whose X-Forwarded-For names
    # the client; "" trusts only 127.0.0.1 (a proxy on this machine); "*" is refused
    trusted_proxies: str = ""
    # wrong researcher tokens per client address (and worker, with memory://) before a
    # lockout (429)
    researcher_lockout: str = "10 per 10 minutes"
    # seconds (>= 1) an idle keep-alive connection stays open: longer than a reverse proxy keeps
    # its idle connections to the server (Caddy 2 min, nginx 60 s), so the proxy always closes
    # first; uvicorn's 5 s raced the proxy reusing a connection the server was closing (a 502,
    # or a reset for a direct client)
    keep_alive_s: int = Field(130, ge=1)
    # how often each worker releases stale sessions' balance counts (balance.sweep_stale)
    stale_sweep_s: float = Field(default=30.0, gt=0)
    # production: researcher token must be strong, API docs off (app/main.py); implied by a
    # non-loopback bind (for_host) or name in allowed_hosts
    production: bool = False
    # bots answer faster than people and report a simulated clock; only `make pilot` sets this
    trust_client_clock: bool = False
    # serve a study although sessions ran another trial bank (app/server/bank_guard.py)
    allow_bank_change: bool = False
    # Prolific's researcher API (app/server/prolific.py): with a token, a Prolific session counts
    # only once Prolific confirms its SESSION_ID (app/server/flow/prolific_check.py)
    prolific_token: str = ""
    # a file holding the Prolific API token (read instead of TOMSTUDY_PROLIFIC_TOKEN)
    prolific_token_file: Path | None = None
    # the base URL of Prolific's researcher API
    prolific_api_url: str = "https://api.prolific.com/api/v1/"
    # seconds (> 0) one request to Prolific's API may take
    prolific_timeout_s: float = Field(default=5.0, gt=0)
    # how often each worker asks Prolific again about sessions it could not check at start
    prolific_recheck_s: float = Field(default=60.0, gt=0)

    @model_validator(mode="after")
    def _read_secret_files(self) -> "Settings":
        if self.admin_token_file is not None:
            self.admin_token = read_secret(self.admin_token_file, "TOMSTUDY_ADMIN_TOKEN_FILE")
        if self.prolific_token_file is not None:
            self.prolific_token = read_secret(self.prolific_token_file,
                                              "TOMSTUDY_PROLIFIC_TOKEN_FILE")
        return self

    @model_validator(mode="after")
    def _public_name_means_production(self) -> "Settings":
        # a name others resolve is a public server, whatever address it binds (a proxy's)
        if self.public_host_names:
            self.production = True
        return self

    @property
    def public_host_names(self) -> list[str]:
        """The names in `allowed_hosts` that are not loopback: each makes this production."""
        return [h for h in self.trusted_hosts if not is_loopback(h)]

    def resolved_database_url(self) -> str:
        """The configured URL (with the password file's password), or SQLite under the data dir."""
        if not self.database_url:
            return f"sqlite:///{self.layout.study_database()}"
        if self.database_password_file is None:
            return self.database_url
        password = read_secret(self.database_password_file, "TOMSTUDY_DATABASE_PASSWORD_FILE")
        return make_url(self.database_url).set(password=password).render_as_string(
            hide_password=False)

    @property
    def layout(self) -> Layout:
        """Every generated path under the data dir."""
        return Layout(self.data_dir, self.recordings_dir)

    @property
    def trusted_hosts(self) -> list[str]:
        """Host header values the server answers: loopback names plus `allowed_hosts`."""
        configured = [h.strip().lower() for h in self.allowed_hosts.split(",") if h.strip()]
        return list(dict.fromkeys([*LOOPBACK_HOSTS, *configured]))

    def for_host(self, host: str) -> "Settings":
        """These settings for a server bound to `host`: production unless `host` is loopback."""
        if self.production or is_loopback(host):
            return self
        return self.model_copy(update={"production": True})


def read_secret(path: Path, name: str) -> str:
    """The secret in `path` without its trailing newline; ValueError naming `name` if unreadable."""
    try:
        return Path(path).read_text().strip()
    except OSError as err:
        raise ValueError(f"{name}: cannot read {path} ({err.strerror})") from None


def is_loopback(host: str) -> bool:
    """True for localhost, 127.0.0.0/8 and ::1: addresses only this machine can reach."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:  # any other name may resolve to a public address
        return False


@lru_cache
def get_settings() -> Settings:
    """The settings of this process (cached)."""
    return Settings()
