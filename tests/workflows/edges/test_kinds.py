"""The table of rig evidence-edge kinds: each is wired to a RigCalibration field and found by its type."""

from __future__ import annotations

import pytest

from calibctl.artifacts.rig import RigCalibration, RigEdge
from calibctl.errors import UsageError
from calibctl.workflows.edges.kinds import EVIDENCE_SOURCES, KINDS, kind_of


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.source)
def test_every_kind_keeps_its_evidence_in_a_rig_calibration_field_and_names_a_legal_source(kind) -> None:
    assert kind.evidence_field in RigCalibration.model_fields
    field_type = str(RigCalibration.model_fields[kind.evidence_field].annotation)
    assert kind.evidence.__name__ in field_type
    assert kind.source in str(RigEdge.model_fields["source"].annotation)


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.source)
def test_kind_of_finds_the_kind_of_each_evidence_type(kind) -> None:
    assert kind_of(kind.evidence.model_construct()) is kind


def test_the_kinds_have_distinct_sources_fields_and_rule_prefixes() -> None:
    for attr in ("source", "evidence_field", "rule", "evidence"):
        values = [getattr(k, attr) for k in KINDS]
        assert len(set(values)) == len(values), attr
    assert tuple(k.source for k in KINDS) == EVIDENCE_SOURCES and "rig-solve" not in EVIDENCE_SOURCES


def test_an_unknown_evidence_type_is_refused() -> None:
    with pytest.raises(UsageError, match="not the evidence of any rig edge kind") as info:
        kind_of(RigEdge.model_construct())
    assert info.value.exit_code == 2
