"""`calibctl rig import FILE`: a rig version from another store (its JSON export or a bundle folder), hash and
signature checked, members found in this store (the same versions or imports of them), this store's verdict
and version, idempotent; every bad input is refused with nothing stored."""

from __future__ import annotations

import json

import pytest

from calibctl.errors import NotFoundError
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.cli.rig.test_rig_export_cli import db, invoke, rig2, solved  # noqa: F401 - fixtures
from tests.cli.rig.test_rig_signature_cli import signed, signed_solved  # noqa: F401 - fixtures
from tests.store.rig_documents import rig_definition
from tests.workflows.rig.test_rig_store_flow import WHO, _truth_artifact


def _text(r):
    return " ".join(r.output.split())


def _rig_versions(url):
    with Store.open(url) as store:
        try:
            return [(c.version, c.status) for c in store.list_rig_calibrations("R1")]
        except NotFoundError:
            return []


def _export_rig(url, path, *args):
    r = invoke(url, "rig", "export", "R1", "--format", "json", "-o", str(path), *args)
    assert r.exit_code == 0, r.output
    return path


def _target(source_url, tmp_path, cameras=("CAM0", "CAM1"), register=True):
    """A second store holding `calibctl import`s of the source's members, rig R1 registered."""
    url = f"sqlite:///{tmp_path / 'target.db'}"
    for cam in cameras:
        path = tmp_path / f"{cam}.json"
        assert invoke(source_url, "export", cam, "-o", str(path)).exit_code == 0
        r = invoke(url, "import", str(path))
        assert r.exit_code == 0, r.output
    if register:
        assert invoke(url, "rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1").exit_code == 0
    return url


def test_a_signed_rig_imports_pinned_to_this_stores_members_once(signed, tmp_path):
    source, trusted, _ = signed
    path = _export_rig(source, tmp_path / "R1.json")
    sent = json.loads(path.read_text())
    url = _target(source, tmp_path)
    r = invoke(url, "rig", "import", str(path), "--require-signature", "--trusted-keys", str(trusted))
    assert r.exit_code == 0, r.output
    assert "imported as R1@1 (accepted by this store's lint, active; source R1@1 was accepted" in _text(r)
    got = json.loads(invoke(url, "--json", "rig", "show", "R1").stdout)
    with Store.open(url) as store:  # the members this store holds: its imports of the source's versions
        here = {s: store.get_artifact(s, None) for s in ("CAM0", "CAM1")}
    assert [(m["serial"], m["version"], m["content_sha256"]) for m in got["members"]] == [
        (s, here[s].version, here[s].content_sha256) for s in ("CAM0", "CAM1")
    ]
    assert [m["content_sha256"] for m in sent["members"]] != [m["content_sha256"] for m in got["members"]]
    assert got["provenance"]["imported_from"].startswith(
        f"R1@1 sha256 {sent['content_sha256']} from station "
    )
    assert got["edges"] == sent["edges"] and got["content_sha256"] != sent["content_sha256"]
    assert invoke(url, "lint", "--rig", "R1").exit_code == 0
    r = invoke(url, "rig", "import", str(path))  # the same content again: a no-op
    assert r.exit_code == 0 and "already stored as R1@1" in _text(r)
    bundle = tmp_path / "bundle"
    assert invoke(source, "rig", "export", "R1", "--format", "bundle", "-o", str(bundle)).exit_code == 0
    for given in (bundle, bundle / "manifest.json"):  # the bundle folder or its manifest
        r = invoke(url, "--json", "rig", "import", str(given))
        assert r.exit_code == 0 and json.loads(r.stdout)["already_imported"] is True
    assert _rig_versions(url) == [(1, "accepted")]
    r = invoke(source, "rig", "import", str(path))  # the source's own export brought back
    assert (
        r.exit_code == 0
        and "already stored as R1@1" in _text(r)
        and _rig_versions(source) == [(1, "accepted")]
    )


def test_an_edited_rig_file_or_bundle_is_exit_1_and_nothing_is_stored(signed, tmp_path):
    source, _, _ = signed
    path = _export_rig(source, tmp_path / "R1.json")
    url = _target(source, tmp_path)
    doc = json.loads(path.read_text())
    doc["edges"][0]["T_parent_child"][0][3] += 0.001  # a baseline one millimetre longer
    path.write_text(json.dumps(doc))
    r = invoke(url, "rig", "import", str(path))
    assert (
        r.exit_code == 1
        and "content does not match its sha256" in _text(r)
        and "nothing was stored" in _text(r)
    )
    bundle = tmp_path / "bundle"
    assert invoke(source, "rig", "export", "R1", "--format", "bundle", "-o", str(bundle)).exit_code == 0
    (bundle / "cam1.yaml").write_text((bundle / "cam1.yaml").read_text().replace("cam1", "cam0"))
    r = invoke(url, "rig", "import", str(bundle))
    assert r.exit_code == 1 and f"{bundle / 'cam1.yaml'} was changed after calibctl wrote it" in _text(r)
    assert _rig_versions(url) == []


def test_a_member_missing_or_another_calibration_here_is_exit_2_naming_the_import(signed, rig2, tmp_path):
    source, _, _ = signed
    path = _export_rig(source, tmp_path / "R1.json")
    url = _target(source, tmp_path, cameras=("CAM0",), register=False)
    with Store.open(url) as store:  # a definition naming CAM1, which this store has no calibration of
        store.add_rig(
            rig_definition("R1").model_copy(
                update={"cameras": ["CAM0", "CAM1"], "root": "CAM0", "design_baselines": []}
            )
        )
    r = invoke(url, "rig", "import", str(path))
    assert r.exit_code == 2 and "member CAM1@1 of rig R1@1 is not in this store; nothing was stored" in _text(
        r
    )
    assert "calibctl import CAM1.json" in _text(r) and _rig_versions(url) == []
    with Store.open(url) as store:  # now CAM1@1 here is this store's own, different calibration
        store.add_board(measured_board(square_mm=25.0))
        store.add_artifact(calibration(serial="CAM1", fx=612.0), activate=True, **WHO)
    r = invoke(url, "rig", "import", str(path))
    assert r.exit_code == 2 and "this store's CAM1@1 is another calibration" in _text(r), r.output
    assert _rig_versions(url) == []


def test_unsigned_or_untrusted_with_require_signature_is_exit_2_and_nothing_is_stored(signed, db, tmp_path):
    source, trusted, other = signed
    url = _target(source, tmp_path)
    unsigned = _export_rig(db, tmp_path / "unsigned.json")  # the same rig solved by an unsigned store
    r = invoke(url, "rig", "import", str(unsigned), "--require-signature", "--trusted-keys", str(trusted))
    assert r.exit_code == 2 and "(R1@1) is not signed" in _text(r)
    path = _export_rig(source, tmp_path / "R1.json")
    r = invoke(url, "rig", "import", str(path), "--require-signature", "--trusted-keys", str(other))
    assert r.exit_code == 2 and "which is not trusted" in _text(r)
    doc = json.loads(path.read_text())
    value = doc["signature"]["value"]
    doc["signature"]["value"] = ("B" if value[0] != "B" else "C") + value[1:]
    path.write_text(json.dumps(doc))
    r = invoke(
        url, "rig", "import", str(path), "--trusted-keys", str(trusted)
    )  # refused even when not required
    assert r.exit_code == 2 and "does not match its content" in _text(r)
    assert _rig_versions(url) == []


def test_a_rig_whose_member_is_not_active_here_is_stored_but_never_activated(signed, rig2, tmp_path):
    source, _, _ = signed
    path = _export_rig(source, tmp_path / "R1.json")
    url = _target(source, tmp_path)
    with Store.open(url) as store:  # CAM0 re-calibrated here since
        store.add_artifact(_truth_artifact(rig2, "CAM0"), activate=True, **WHO)
    r = invoke(url, "rig", "import", str(path))
    assert r.exit_code == 1 and "imported as R1@1 (accepted by this store's lint, not active" in _text(r)
    assert "rig-stale-member" in _text(r)
    with Store.open(url) as store:
        assert store.active_rig_version("R1") is None
    assert _rig_versions(url) == [(1, "accepted")]


def test_a_rig_not_registered_here_is_exit_2(signed, tmp_path):
    source, _, _ = signed
    path = _export_rig(source, tmp_path / "R1.json")
    url = _target(source, tmp_path, register=False)
    r = invoke(url, "rig", "import", str(path))
    assert r.exit_code == 2 and "unknown rig 'R1'" in _text(r) and "calibctl rig add" in _text(r)


def test_a_rig_registered_here_with_another_layout_is_exit_2(signed, tmp_path):
    source, _, _ = signed
    path = _export_rig(source, tmp_path / "R1.json")
    url = _target(source, tmp_path, register=False)
    assert (
        invoke(url, "rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1", "--root", "CAM1").exit_code
        == 0
    )
    r = invoke(url, "rig", "import", str(path))
    assert r.exit_code == 2 and "is not the rig R1 registered here" in _text(r) and "root CAM1" in _text(r)
    assert _rig_versions(url) == []


@pytest.mark.parametrize("content", ['{"hello": 1}', "not json"])
def test_a_file_that_is_no_rig_export_is_exit_2(signed, tmp_path, content):
    source, _, _ = signed
    path = tmp_path / "x.json"
    path.write_text(content)
    r = invoke(source, "rig", "import", str(path))
    assert r.exit_code == 2, r.output


def test_an_unsigned_rig_into_a_store_with_keys_is_stored_but_not_active_unless_asked(signed, db, tmp_path):
    source, trusted, _ = signed
    unsigned = _export_rig(db, tmp_path / "unsigned.json")  # the same rig solved by an unsigned store
    url = _target(source, tmp_path)
    r = invoke(
        url, "rig", "import", str(unsigned), "--trusted-keys", str(trusted)
    )  # keys: signatures required
    assert r.exit_code == 0, r.output
    assert "imported unsigned, not active (this store requires signatures; --activate to override)" in _text(
        r
    )
    with Store.open(url) as store:
        assert store.active_rig_version("R1") is None
    assert _rig_versions(url) == [(1, "accepted")]
    other = tmp_path / "other"
    other.mkdir()
    url2 = _target(source, other)
    r = invoke(url2, "--json", "rig", "import", str(unsigned), "--trusted-keys", str(trusted), "--activate")
    assert (
        r.exit_code == 0
        and json.loads(r.stdout)["active"] is True
        and json.loads(r.stdout)["held_back"] is None
    )
    with Store.open(url2) as store:
        assert store.active_rig_version("R1") == 1
    events = json.loads(invoke(url2, "--json", "rig", "history", "R1").stdout)
    assert "activated with --activate although this store requires signatures" in json.dumps(events)
