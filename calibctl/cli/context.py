"""Per-invocation state the global options resolve to; every command module reads it from here."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import typer

if TYPE_CHECKING:
    from calibctl.config import Settings


@dataclass
class AppState:
    db: str | None = None
    station_config: Path | None = None
    json_output: bool = False

    def settings(
        self, station: str | None = None, operator: str | None = None, jobs: int | None = None
    ) -> Settings:
        from calibctl.config import load_settings  # pydantic + yaml: not needed for --help or --version

        return load_settings(
            db=self.db, station_config=self.station_config, station=station, operator=operator, jobs=jobs
        )


def state(ctx: typer.Context) -> AppState:
    """The global options of this invocation (works from sub-command groups too)."""
    root = ctx.find_root()
    if not isinstance(root.obj, AppState):
        root.obj = AppState()
    return root.obj


def wants_json(ctx: typer.Context, local_flag: bool = False) -> bool:
    """True when either the global ``--json`` or the command's own ``--json`` was given."""
    return local_flag or state(ctx).json_output
