"""Child processes of the mixed-load test: station writers and rollback technicians on one store."""

from __future__ import annotations

from typing import Any

from calibctl.errors import CalibctlError, StaleActiveVersionError
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration


def station(url: str, serial: str, count: int, worker: int, barrier: Any, results: Any) -> None:
    """Add ``count`` activated versions of ``serial``; report ("write", versions, gave_up, other errors)."""
    versions, gave_up, errors = [], 0, []
    barrier.wait()
    with Store.open(url) as store:
        for i in range(count):
            try:
                art = calibration(serial=serial, fx=800.0 + worker + i / 100)
                versions.append(
                    store.add_artifact(
                        art, activate=True, actor=f"w{worker}", station=f"st{worker}", reason="load"
                    ).version
                )
            except CalibctlError as exc:
                gave_up += "gave up" in exc.message
                errors.append(exc.message)
    results.put(("write", serial, versions, gave_up, errors))


STALE_RETRIES = 1000  # per rollback; the writers stop after their few versions, so a retry soon wins


def technician(url: str, serial: str, count: int, worker: int, barrier: Any, results: Any) -> None:
    """``count`` rollbacks of ``serial`` to v1/v2, each decided on the active version read just before
    (compare-and-set, as ``calibctl rollback`` does); report how many were done or refused as stale."""
    done, stale, gave_up, errors = 0, 0, 0, []
    barrier.wait()
    with Store.open(url) as store:
        for i in range(count):
            # a refusal as stale is the compare-and-set working; decide again on a fresh read, as a
            # technician would, so every rollback is done once the writers let it (on a loaded machine the
            # writers won all 40 races of a run, and "some rollback was done" failed)
            for _ in range(STALE_RETRIES):
                seen = store.active_version(serial)
                target = 1 if seen != 1 else 2
                try:
                    store.rollback(
                        serial,
                        target,
                        reason=f"r{worker}.{i}",
                        actor=f"t{worker}",
                        station="van",
                        expected_active=seen,
                    )
                    done += 1
                    break
                except StaleActiveVersionError:
                    stale += 1
                except CalibctlError as exc:
                    gave_up += "gave up" in exc.message
                    errors.append(exc.message)
                    break
    results.put(("rollback", serial, [done, stale], gave_up, errors))
