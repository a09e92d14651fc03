"""schemas/ is generated from the models; any drift fails here (run `make schemas` and review the diff)."""

from __future__ import annotations

from pathlib import Path

from calibctl.artifacts.schema_export import expected_files

SCHEMAS = Path(__file__).resolve().parents[2] / "schemas"


def test_committed_schemas_match_the_models():
    expected = expected_files()
    committed = {p.name: p.read_text(encoding="utf-8") for p in SCHEMAS.glob("*.schema.json")}
    assert sorted(committed) == sorted(expected), "schema files added or removed: run `make schemas`"
    drifted = [name for name, text in expected.items() if committed[name] != text]
    assert not drifted, f"schemas drifted from the models: {drifted}; run `make schemas` and commit the diff"


def test_every_field_is_documented():
    import json

    undocumented = []
    for name, text in expected_files().items():
        schema = json.loads(text)
        for def_name, definition in [("(root)", schema), *schema.get("$defs", {}).items()]:
            for field, spec in definition.get("properties", {}).items():
                if "description" not in spec:
                    undocumented.append(f"{name}:{def_name}.{field}")
    assert not undocumented, undocumented
