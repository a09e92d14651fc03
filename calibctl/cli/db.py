"""calibctl db upgrade | current | verify: create and migrate the store, and prove nothing was changed."""

from __future__ import annotations

from typing import Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.options import TrustedKeysOption
from calibctl.cli.render import emit_json, say, stderr
from calibctl.errors import EXIT_VERDICT_FAIL

JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]

db_app = typer.Typer(
    name="db",
    help="Create and migrate the store (SQLite or PostgreSQL) and verify its hash chains and signatures.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


def _counts_text(counts: dict[str, int]) -> str:
    order = ("artifacts", "serials", "boards", "sessions", "events", "images")
    return ", ".join(f"{counts[k]} {k}" for k in order if k in counts)


@db_app.command("upgrade")
def upgrade(ctx: typer.Context, json_output: JsonFlag = False) -> None:
    """Create the database at the newest schema, or migrate an older one keeping its data."""
    from calibctl.workflows.store_admin import database

    result = database.upgrade(state(ctx).settings())
    if wants_json(ctx, json_output):
        emit_json(result.as_json())
        return
    if not result.changed:
        say(f"{result.url}: already at {result.after} (head); nothing to do")
    elif result.before is None:
        say(f"{result.url}: created at {result.after} (head)")
    else:
        say(f"{result.url}: upgraded {result.before} -> {result.after} (head)")


@db_app.command("current")
def current(ctx: typer.Context, json_output: JsonFlag = False) -> None:
    """Show the database's schema revision against this calibctl's (and what the store holds)."""
    from calibctl.workflows.store_admin import database

    status = database.status(state(ctx).settings())
    if wants_json(ctx, json_output):
        emit_json(status.as_json())
        return
    say(f"database  {status.url} ({status.backend})")
    say(f"revision  {status.current or '-'}")
    say(f"head      {status.head}")
    say(f"status    {status.description}")
    if status.counts is not None:
        say(f"holds     {_counts_text(status.counts)}")


@db_app.command("verify")
def verify(
    ctx: typer.Context,
    json_output: JsonFlag = False,
    head: Annotated[
        bool, typer.Option("--head", help="Print the chain head (keep it: --since HEAD resumes from it).")
    ] = False,
    since: Annotated[
        str | None,
        typer.Option(
            "--since",
            metavar="HEAD",
            help="Check only what was written after this chain head (after proving the head unchanged).",
        ),
    ] = None,
    trusted_keys: TrustedKeysOption = None,
    require_signature: Annotated[
        bool, typer.Option("--require-signature", help="An unsigned record is a finding.")
    ] = False,
) -> None:
    """Check every hash chain, signature, version counter, activation event and stored hash. Exit 1 naming
    each problem."""
    from calibctl.workflows.store_admin import database

    report = database.verify(
        state(ctx).settings(), trusted_keys=trusted_keys, require_signature=require_signature, since=since
    )
    if wants_json(ctx, json_output):
        emit_json(report.as_json())
    else:
        for line in report.problems:
            say(f"PROBLEM {line}")
        verdict = "all intact" if report.ok else f"{len(report.problems)} problem(s)"
        scope = (
            f"{report.records_checked} chained records since the given head"
            if since
            else _counts_text(report.counts)
        )
        say(f"verified {scope} in {report.url}: {verdict}")
        if not report.trusted_keys:
            say(
                f"signatures: not checked (no signing key or trusted keys configured); {report.unsigned} "
                "unsigned record(s)"
            )
        else:
            say(
                f"signatures: {report.signatures_checked} checked against {report.trusted_keys} trusted "
                "key(s); "
                f"{report.unsigned} unsigned record(s)"
            )
        if report.orphan_images:
            say(
                f"images: {report.orphan_images} file(s) no record refers to (left by a failed capture; "
                "`calibctl prune` removes them)"
            )
        if head:
            say(f"head {report.head}")
    if not report.ok:
        stderr.print(
            f"Error: {len(report.problems)} problem(s) in the stored history; restore the named records "
            "from an "
            "export or a backup",
            soft_wrap=True,
            markup=False,
        )
        raise typer.Exit(EXIT_VERDICT_FAIL)


def register(app: typer.Typer) -> None:
    """Add the ``db`` command group to the root app."""
    app.add_typer(db_app, name="db")
