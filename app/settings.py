"""Process-wide settings, read once from the environment (prefix TOMSTUDY_)."""

import ipaddress
from functools import lru_cache
from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

from app.layout import DEFAULT_DATA_DIR, Layout

REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_ADMIN_TOKEN = "change-me-researcher-token"


class Settings(BaseSettings):
    """Where data lives, which database to use and how researchers authenticate."""

    model_config = SettingsConfigDict(env_prefix="TOMSTUDY_", extra="ignore")

    data_dir: Path = Field(default=DEFAULT_DATA_DIR)
    configs_dir: Path = Field(default=REPO_ROOT / "study_configs")
    database_url: str = Field(default="", validation_alias="DATABASE_URL")
    admin_token: str = DEFAULT_ADMIN_TOKEN
    # production: researcher token must be strong, API docs off (app/study/main.py)
    production: bool = False
    # bots answer faster than people and report a simulated clock; only `make pilot` sets this
    trust_client_clock: bool = False
    # serve a study although sessions ran another trial bank (app/study/bank_guard.py)
    allow_bank_change: bool = False

    def resolved_database_url(self) -> str:
        """The configured URL, or SQLite under the data dir."""
        return self.database_url or f"sqlite:///{self.layout.study_database()}"

    @property
    def layout(self) -> Layout:
        """Every generated path under the data dir."""
        return Layout(self.data_dir)

    def for_host(self, host: str) -> "Settings":
        """These settings for a server bound to `host`: production unless `host` is loopback."""
        if self.production or is_loopback(host):
            return self
        return self.model_copy(update={"production": True})


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
