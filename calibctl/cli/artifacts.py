"""history, show, export, import, rollback: what a field technician runs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import TrustedKeysOption
from calibctl.errors import EXIT_VERDICT_FAIL

# render and report (rich) are imported by the commands that print with them: `export` prints the exported
# text as it is, and does not pay rich's import (42-51 ms of import self time, benchmarks/results/startup.md).

JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]


def history(
    ctx: typer.Context,
    serial: Annotated[str, typer.Argument(help="Camera serial number.")],
    json_output: JsonFlag = False,
) -> None:
    """Versions of a camera's calibration, the active one, and every activation/rollback event."""
    from calibctl.cli.render import emit_json, plain, stdout
    from calibctl.cli.report import history_table
    from calibctl.workflows.store_admin import records

    hist = records.history(state(ctx).settings(), serial)
    if wants_json(ctx, json_output):
        emit_json(hist.as_json())
        return
    stdout.print(history_table(hist.versions, serial))
    if hist.events:
        stdout.print("events:")
        for e in hist.events:
            prev = f" (was {e.previous_version})" if e.previous_version else ""
            stdout.print(
                f"  {e.at.isoformat()[:19].replace('T', ' ')}  {e.kind:<8} -> v{e.version}{prev}  "
                f"by {plain(e.actor)} at {plain(e.station)}: {plain(e.reason)}",
                markup=False,
                soft_wrap=True,
            )
    if hist.checks:
        stdout.print("checks:")
        for c in hist.checks:
            stdout.print(
                f"  {c.at.isoformat()[:19].replace('T', ' ')}  check    v{c.version}  "
                f"{'pass' if c.passed else 'FAIL'}  {len(c.views)} views, RMS "
                f"{c.regions[0].check_rms_px or 0:.3f} px  by {c.operator} at {c.station}"
                + (f": {c.reasons[0]}" if c.reasons else ""),
                markup=False,
                highlight=False,
            )


def show(
    ctx: typer.Context,
    ref: Annotated[
        str, typer.Argument(metavar="SERIAL[@N]", help="Serial, optionally @version (default: active).")
    ],
    json_output: JsonFlag = False,
) -> None:
    """One calibration in full: parameters with their one-sigma, held-out error, gates and lint."""
    from calibctl.cli.render import emit_json
    from calibctl.cli.report import print_calibration
    from calibctl.workflows.store_admin import records

    art = records.show(state(ctx).settings(), ref)
    if wants_json(ctx, json_output):
        emit_json(art)
        return
    print_calibration(art)


def export(
    ctx: typer.Context,
    ref: Annotated[
        str, typer.Argument(metavar="SERIAL[@N]", help="Serial, optionally @version (default: active).")
    ],
    fmt: Annotated[
        str,
        typer.Option("--format", "-f", help="json | yaml | ros | opencv | kalibr | mrcal | lut (-o DIR)"),
    ] = "json",
    out: Annotated[Path | None, typer.Option("--output", "-o", help="Write here instead of stdout.")] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Overwrite an existing --output file (keeps its mode).")
    ] = False,
    allow_rejected: Annotated[
        bool, typer.Option("--allow-rejected", help="Export a rejected version too (marked rejected).")
    ] = False,
    camera_name: Annotated[
        str | None, typer.Option("--camera-name", help="ROS camera_name ([A-Za-z0-9_]; default: the serial).")
    ] = None,
    topic: Annotated[
        str | None,
        typer.Option("--topic", help="kalibr: the camera's rostopic (default /<frame>/image_raw)."),
    ] = None,
    alpha: Annotated[
        float | None,
        typer.Option(
            "--alpha", help="lut, pinhole lens: 0 keeps only valid pixels (default), 1 every pixel."
        ),
    ] = None,
    balance: Annotated[
        float | None,
        typer.Option(
            "--balance", help="lut, fisheye lens: 0 keeps only valid pixels (default), 1 every pixel."
        ),
    ] = None,
) -> None:
    """Export what a robot needs: the artifact (json/yaml), ROS camera_info YAML, OpenCV FileStorage, or the
    undistortion maps cv2.remap reads (lut: a folder of .npy maps and a signed lut.yaml)."""
    from calibctl.workflows.store_admin import records

    if fmt == "lut":
        for path in records.export_lut(
            state(ctx).settings(),
            ref,
            out,
            force=force,
            allow_rejected=allow_rejected,
            alpha=alpha,
            balance=balance,
            camera_name=camera_name,
            topic=topic,
        ):
            print(f"wrote {path}", flush=True)
        return
    text = records.export(
        state(ctx).settings(),
        ref,
        fmt,
        out,
        force=force,
        allow_rejected=allow_rejected,
        camera_name=camera_name,
        lut_options=alpha is not None or balance is not None,
        topic=topic,
    )
    if out is None:
        print(text, end="")
    else:
        print(f"wrote {out}", flush=True)


def import_(
    ctx: typer.Context,
    path: Annotated[Path, typer.Argument(metavar="FILE", help="An artifact exported with --format json.")],
    activate: Annotated[
        bool | None,
        typer.Option(
            "--activate/--no-activate",
            help="Make it active when this store accepts it. Default: active when accepted "
            "and signed by a trusted key, or when this store has no keys; --activate overrides (recorded).",
        ),
    ] = None,
    keep_version: Annotated[
        bool,
        typer.Option(
            "--keep-version", help="Keep the source version number (only when it is this store's next one)."
        ),
    ] = False,
    require_signature: Annotated[
        bool, typer.Option("--require-signature", help="Refuse a file not signed by a trusted key (exit 2).")
    ] = False,
    trusted_keys: TrustedKeysOption = None,
    json_output: JsonFlag = False,
) -> None:
    """Bring an exported artifact into this store: its hash and signature are checked (tampered files exit 1),
    its numbers are linted with this store's rules, and the verdict and version are this store's."""
    from calibctl.cli.render import emit_json, stdout
    from calibctl.cli.report import print_findings
    from calibctl.workflows.lint import (
        imports,  # lint, numpy and the lens checks: not for history/show/export
    )

    outcome = imports.import_file(
        state(ctx).settings(),
        path,
        activate=activate,
        keep_version=keep_version,
        require_signature=require_signature,
        trusted_keys=trusted_keys,
    )
    art = outcome.artifact
    if wants_json(ctx, json_output):
        emit_json(
            {
                "artifact": art.model_dump(mode="json"),
                "source": outcome.source_ref,
                "source_status": outcome.source_status,
                "active": outcome.active,
                "already_imported": outcome.already_imported,
                "held_back": outcome.held_back,
            }
        )
    else:
        again = "already stored as" if outcome.already_imported else "imported"
        state_word = "active" if outcome.active else "not active"
        stdout.print(
            f"{again} {art.serial}@{art.version} ({art.status} by this store's lint, {state_word}; "
            f"source {outcome.source_ref} was {outcome.source_status}; sha256 {art.content_sha256[:12]})",
            markup=False,
        )
        if outcome.held_back:
            stdout.print(outcome.held_back, markup=False)
        if art.status == "rejected":
            print_findings([f for f in art.lint if f.severity == "error"])
    if (
        activate is not False and art.status == "rejected"
    ):  # asked to make it active; this store's verdict says no
        raise typer.Exit(EXIT_VERDICT_FAIL)


def rollback(
    ctx: typer.Context,
    serial: Annotated[str, typer.Argument(help="Camera serial number.")],
    to: Annotated[int, typer.Option("--to", help="Version to make active.")],
    reason: Annotated[str, typer.Option("--reason", help="Why; kept forever in the event log.")],
    expect_active: Annotated[
        int | None,
        typer.Option(
            "--expect-active", help="The active version you decided on; refused if it has changed since."
        ),
    ] = None,
    json_output: JsonFlag = False,
) -> None:
    """Make an earlier accepted version active again (an append-only event; nothing is deleted). A newer
    version activated by someone else in the meantime makes it refuse (exit 2) instead of undoing it.
    A version that is active already is a success that writes nothing."""
    from calibctl.cli.render import emit_json, stdout
    from calibctl.workflows.store_admin import records

    event = records.rollback(state(ctx).settings(), serial, to, reason, expected_active=expect_active)
    if event is None:
        if wants_json(ctx, json_output):
            emit_json({"serial": serial, "version": to, "already_active": True})
        else:
            stdout.print(f"{serial}: v{to} is already the active version; nothing written", markup=False)
        return
    if wants_json(ctx, json_output):
        emit_json(event)
        return
    was = f" (was v{event.previous_version})" if event.previous_version else ""
    stdout.print(f"{serial}: active version is now v{event.version}{was}", markup=False)


def register(app: typer.Typer) -> None:
    app.command("history")(history)
    app.command("show")(show)
    app.command("export")(export)
    app.command("import")(import_)
    app.command("rollback")(rollback)
