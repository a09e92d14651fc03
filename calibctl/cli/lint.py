"""calibctl lint: exit 0 clean, 1 errors found, 2 an input could not be read."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import TrustedKeysOption
from calibctl.cli.plain_text import emit_json, finding_lines, plain, terminal_paint
from calibctl.errors import EXIT_VERDICT_FAIL, UsageError

FORMATS = ("text", "json", "github")


def _github_line(source: str, f) -> str:
    level = {"error": "error", "warning": "warning"}.get(f.severity, "notice")
    message = f.message + (f" Fix: {f.fix}" if f.fix else "")
    message = message.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")
    return f"::{level} file={source},title=calibctl {f.rule}::{message}"


def lint(
    ctx: typer.Context,
    files: Annotated[
        list[Path] | None,
        typer.Argument(
            metavar="[FILE...]",
            help="Any calibctl export (artifact JSON/YAML, ROS camera_info, OpenCV FileStorage "
            "YAML/XML/JSON), any rig export (tf, URDF, Kalibr, OpenCV stereo, mrcal, a bundle's "
            "manifest.json), a LUT folder or its lut.yaml (with --db: refused when stale) or a ROS "
            "camera_info file.",
        ),
    ] = None,
    serial: Annotated[
        str | None, typer.Option("--serial", help="Lint this serial's active version in the store.")
    ] = None,
    all_serials: Annotated[
        bool, typer.Option("--all", help="Lint the active version of every serial in the store.")
    ] = False,
    rig: Annotated[
        str | None,
        typer.Option(
            "--rig",
            help="Lint a rig's active version (RIG or RIG@N): stale members, "
            "design baseline, epipolar, loop closure, members.",
        ),
    ] = None,
    fmt: Annotated[
        str, typer.Option("--format", help="text | json | github (workflow annotations)")
    ] = "text",
    json_output: Annotated[bool, typer.Option("--json", help="Same as --format json.")] = False,
    require_signature: Annotated[
        bool, typer.Option("--require-signature", help="Anything not signed by a trusted key is an error.")
    ] = False,
    trusted_keys: TrustedKeysOption = None,
) -> None:
    """Check calibrations the way CI should: principal point, sigma(fx), held-out outer ring, provenance,
    hash."""
    from calibctl.core.blas_threads import blas_starts_on_one_thread

    with blas_starts_on_one_thread():  # lint computes on a few small arrays: no BLAS worker threads to start
        from calibctl.workflows.lint import run as lint_workflow

    if fmt not in FORMATS:
        raise UsageError(f"unknown --format '{fmt}'", f"choose one of {', '.join(FORMATS)}")
    if wants_json(ctx, json_output):
        fmt = "json"
    st = state(ctx)
    results = (
        lint_workflow.lint(
            st.settings(),
            files or [],
            serial,
            all_serials,
            require_signature=require_signature,
            trusted_keys=trusted_keys,
            against_store=st.db is not None or bool(os.environ.get("CALIBCTL_DB")),
        )
        if (files or serial or all_serials or not rig)
        else []
    )
    if rig:
        from calibctl.workflows.rig.rig_lint import lint_rig
        from calibctl.workflows.store_admin.keys import trusted_of

        trusted = trusted_of(st.settings(), trusted_keys) if require_signature else None
        if trusted is not None and not trusted.keys:
            raise UsageError(
                "--require-signature needs trusted keys", "pass --trusted-keys DIR or set trusted_keys"
            )
        results.append(lint_rig(st.settings(), rig, trusted))
    failed = any(r.failed for r in results)
    if fmt == "json":
        emit_json({"verdict": "fail" if failed else "pass", "results": [r.as_json() for r in results]})
    elif fmt == "github":
        for r in results:
            for f in r.findings:
                print(_github_line(r.source, f))
        print(f"calibctl lint: {sum(r.failed for r in results)} of {len(results)} calibration(s) failed")
    else:
        for r in results:  # plain print: `lint FILE` starts without importing rich (calibctl.cli.plain_text)
            verdict = terminal_paint("red", "FAIL") if r.failed else terminal_paint("green", "pass")
            print(f"{plain(r.source)} ({r.kind}): {verdict}")
            for line in finding_lines(r.findings, terminal_paint):
                print(line)
    if failed:
        raise typer.Exit(EXIT_VERDICT_FAIL)


def register(app: typer.Typer) -> None:
    app.command("lint")(lint)
