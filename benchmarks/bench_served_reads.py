"""What checking each served record (chain link and signature, ``calibctl.store.served``) costs a read,
with and without keys configured.

    .venv/bin/python benchmarks/bench_served_reads.py [--repeats 7] [--serials 200]

A SQLite store made by ``calibctl demo`` (one board, one calibration) is signed from then on: the demo's
artifact is re-stored under ``--serials`` serials with a signing key (``calibctl keys init``), each
activated. Then, each ``--repeats`` times:
- ``show``, ``export --format ros`` and ``lint --serial`` of one serial in a fresh process, without keys and
  with ``CALIBCTL_TRUSTED_KEYS`` (the station's public key): best and median CPU time of the child (the two
  interleaved);
- in-process: ``Store.get_artifact`` of the active version (300 reads) and ``active_artifacts`` of every
  serial (``lint --all``'s read), with and without ``trusted``: milliseconds per record.
Nothing is asserted; the machine is shared, so the load average is printed first.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import cpu_model

REPO = Path(__file__).resolve().parents[1]
SERIAL = "DEMO-CAM-0001"


def _env(extra: dict[str, str] | None = None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("CALIBCTL_")}
    env["PYTHONPATH"] = str(REPO)
    return env | (extra or {})


def _make_store(work: Path, serials: int) -> tuple[str, Path]:
    from calibctl.signing import create_key
    from calibctl.store.repository import Store

    subprocess.run(
        [sys.executable, "-m", "calibctl", "demo"], cwd=work, env=_env(), check=True, capture_output=True
    )
    db = f"sqlite:///{work / 'demo-out/calibctl-demo.db'}"
    signer = create_key(work / "station.pem")
    keys = work / "trusted"
    keys.mkdir()
    (keys / "station.pem").write_text(signer.public_pem())
    with Store.open(db, signer=signer) as store:
        art = store.get_artifact(SERIAL)
        store.add_artifact(art, activate=True, reason="signed copy", actor="bench", station="bench")
        for i in range(1, serials):
            store.add_artifact(
                art.model_copy(update={"serial": f"CAM-{i:05d}"}),
                activate=True,
                reason="bench",
                actor="bench",
                station="bench",
            )
    return db, keys


def _time_pair(
    argv: list[str], plain_env: dict[str, str], keyed_env: dict[str, str], repeats: int
) -> tuple[list[float], list[float]]:
    """CPU times (user + system) of ``argv`` without and with keys, the two interleaved so the shared
    machine's
    load falls on both alike (after one warm-up each: file cache, .pyc); wall time on a loaded machine mostly
    measures the load."""
    times: tuple[list[float], list[float]] = ([], [])
    for env in (plain_env, keyed_env):
        subprocess.run(argv, env=env, check=True, capture_output=True)
    for _ in range(repeats):
        for out, env in zip(times, (plain_env, keyed_env), strict=True):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            subprocess.run(argv, env=env, check=True, capture_output=True)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            out.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return times


def _per_record(work: Path, db: str, keys: Path, repeats: int) -> None:
    from calibctl.signing import TrustedKeys
    from calibctl.store.repository import Store

    trusted = TrustedKeys.load(keys)
    print(
        "\n| in-process read | records | without keys, ms/record | with keys, ms/record "
        "|\n|---|---:|---:|---:|"
    )
    for label, n, work_fn in (
        ("Store.get_artifact (active)", 300, lambda store: [store.get_artifact(SERIAL) for _ in range(300)]),
        ("Store.active_artifacts (lint --all)", None, lambda store: store.active_artifacts()),
    ):
        best: dict[bool, float] = {}
        count = n
        for with_keys in (False, True):
            with Store.open(db, trusted=trusted if with_keys else None) as store:
                runs = []
                for _ in range(repeats):
                    t0 = time.process_time()
                    out = work_fn(store)
                    runs.append(time.process_time() - t0)
                count = n or len(out[0])
                best[with_keys] = min(runs) / count * 1e3
        print(f"| {label} | {count} | {best[False]:.3f} | {best[True]:.3f} |")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--serials", type=int, default=200)
    args = parser.parse_args()
    print(f"machine: {cpu_model()}, {os.cpu_count()} cores; load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        db, keys = _make_store(work, args.serials)
        print(
            "\n| command (fresh process) | without keys, CPU s best / median | with keys, CPU s best / "
            "median |\n|---|---:|---:|"
        )
        for name, sub in (
            ("show", ["show", SERIAL]),
            ("export --format ros", ["export", SERIAL, "--format", "ros"]),
            ("lint --serial", ["lint", "--serial", SERIAL]),
        ):
            argv = [sys.executable, "-m", "calibctl", "--db", db, *sub]
            plain, keyed = _time_pair(argv, _env(), _env({"CALIBCTL_TRUSTED_KEYS": str(keys)}), args.repeats)
            print(
                f"| {name} | {min(plain):.3f} / {statistics.median(plain):.3f} | "
                f"{min(keyed):.3f} / {statistics.median(keyed):.3f} |"
            )
        _per_record(work, db, keys, args.repeats)


if __name__ == "__main__":
    main()
