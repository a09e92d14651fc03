"""calibctl capture commands."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from calibctl.cli.context import wants_json
from calibctl.cli.render import emit_json, stdout
from calibctl.workflows import synth as synth_workflow


class Scenario(StrEnum):
    good = "good"
    flat = "flat"
    centre = "centre"
    one_direction = "one-direction"
    video = "video"


class Pattern(StrEnum):
    chessboard = "chessboard"
    charuco = "charuco"


def register(app: typer.Typer) -> None:
    """Add this module's commands to the root app."""
    register_synth(app)


def register_synth(app: typer.Typer) -> None:
    """``calibctl synth``: ground-truth board photos (no store involved)."""

    @app.command("synth")
    def synth(
        ctx: typer.Context,
        out: Annotated[Path, typer.Argument(metavar="OUT", help="Output folder (created; must be empty unless --force).")],
        scenario: Annotated[Scenario, typer.Option("--scenario", help="Which session to stage.")] = Scenario.good,
        seed: Annotated[int, typer.Option("--seed", help="Random seed; the same seed gives the same files.")] = 0,
        views: Annotated[
            int | None,
            typer.Option("--views", help="Views to render (video: key poses). Default 12 (video: 8).", show_default=False),
        ] = None,
        size: Annotated[str, typer.Option("--size", help="Image size WxH; the seed's lens is scaled to it.")] = "640x480",
        pattern: Annotated[Pattern, typer.Option("--pattern", help="Board pattern (9x6 inner corners, 25 mm).")] = (
            Pattern.chessboard),
        force: Annotated[bool, typer.Option("--force", help="Write into a non-empty OUT, replacing earlier synth files.")] = False,
        json_output: Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")] = False,
    ) -> None:
        """Render a synthetic capture session through a known camera and write truth.json beside it.

        Scenarios: good (passes every gate), flat (tilt < 5 deg), centre (board only in the middle),
        one-direction (every tilt toward the right), video (an MJPG .avi of a hand-held sweep with pauses).
        """
        result = synth_workflow.run_synth(out, scenario.value, seed, views, synth_workflow.parse_size(size),
                                          pattern.value, force)
        if wants_json(ctx, json_output):
            emit_json(result.as_json())
            return
        what = "1 video" if scenario is Scenario.video else f"{len(result.files)} images"
        stdout.print(f"wrote {what} ({result.n_views} {'frames' if scenario is Scenario.video else 'views'}, "
                     f"{result.image_size[0]}x{result.image_size[1]}, scenario {result.scenario}) "
                     f"and {result.truth_path.name} to {result.out_dir}")
