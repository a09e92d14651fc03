"""calibctl keys init | export-public: the Ed25519 key pair a store or station signs its records with."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from calibctl.cli.context import state, wants_json
from calibctl.cli.render import emit_json, say

JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]
KeyOption = Annotated[
    Path | None,
    typer.Option(
        "--key",
        metavar="FILE",
        help="Private key file (default: the signing_key setting, CALIBCTL_SIGNING_KEY).",
    ),
]
ForceFlag = Annotated[bool, typer.Option("--force", help="Replace an existing file.")]

keys_app = typer.Typer(
    name="keys",
    help="Create the signing key pair and export its public key for other systems' trusted-keys folders.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


@keys_app.command("init")
def init(
    ctx: typer.Context, key: KeyOption = None, force: ForceFlag = False, json_output: JsonFlag = False
) -> None:
    """Create an Ed25519 key pair; the private key file gets mode 0600. Records written afterwards are
    signed."""
    from calibctl.workflows.store_admin import keys

    info = keys.init_key(state(ctx).settings(), key, force=force)
    if wants_json(ctx, json_output):
        emit_json(info.as_json())
        return
    say(f"created signing key {info.path} (mode 0600), key id {info.key_id}")
    say("keep it out of the database and its backups; share the public key: calibctl keys export-public")


@keys_app.command("export-public")
def export_public(
    ctx: typer.Context,
    key: KeyOption = None,
    out: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="Write the PEM here (e.g. into a trusted-keys folder)."),
    ] = None,
    force: ForceFlag = False,
    json_output: JsonFlag = False,
) -> None:
    """Print (or write) the public key in PEM; its key id is the sha256 of the raw public key."""
    from calibctl.workflows.store_admin import keys

    info = keys.export_public(state(ctx).settings(), key, out, force=force)
    if wants_json(ctx, json_output):
        emit_json(info.as_json())
    elif out is None:
        print(info.public_pem, end="")
    else:
        say(f"wrote {out} (key id {info.key_id})")


def register(app: typer.Typer) -> None:
    app.add_typer(keys_app, name="keys")
