"""Hostile-input sweep: run hostile or mistaken inputs against every command group and classify each result.

    python benchmarks/hostile_sweep.py [--only GROUP] [--name TEXT] [--json OUT]

Each case runs ``python -m calibctl`` in a process of its own (a segfault is seen as one), in a temporary
folder holding a copy of a demo store (one accepted, active camera DEMO-CAM-0001 on board demo-A17).
Special files are made in that folder (mkfifo, ln -s), never a system device node. Categories:

* clean: exit 1 or 2 with a message (or exit 0 where the input is valid and the command should work)
* stored: the store gained rows although the command was refused or should have been
* lost: a row disappeared, a file the case protects was replaced or changed, or `db verify` fails after
* crash: a traceback, a signal, an exit code outside 0/1/2/130, or no answer within the time limit
* accepted: exit 0 on an input the command should have refused
* refused: exit 1/2 on an input the command should accept (a read-only store's reads)
* misnamed: the command answered as it should, but its words miss what the case says the real mistake is
  (``Case.says``: the board's size, the lens model, a non-regular file...): its hint sends the user elsewhere
* setup: the sweep could not prepare the case (its own fault; not a finding)

``--source DIR`` runs another calibctl tree (e.g. ``git archive BASE calibctl | tar -x -C DIR``) for a
before/after table.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import signal
import sqlite3
import stat
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SOURCE = [REPO]  # the calibctl tree under test (--source)
SERIAL, BOARD = "DEMO-CAM-0001", "demo-A17"
CASE_TIMEOUT_S = 120
UNPRIVILEGED = ["setpriv", "--bounding-set=-dac_override,-dac_read_search,-fowner", "--"]
CATEGORIES = ("clean", "stored", "lost", "crash", "accepted", "refused", "misnamed", "setup")


@dataclass
class Case:
    group: str
    name: str
    args: list[str]
    expect: str = (
        "refuse"  # "ok": a valid input the command should take; "any": either (an interrupted command)
    )
    setup: Callable[[Path], None] | None = None
    protect: list[str] = field(default_factory=list)  # paths under the case folder that must stay as they are
    unprivileged: bool = False
    interrupt_s: float | None = None
    env: dict[str, str] = field(default_factory=dict)
    says: tuple[str, ...] = ()  # words the output (stdout and stderr) must hold: the real mistake, named


# ---- setup helpers (each takes the case folder)
# -------------------------------------------------------------


def fifo(name: str) -> Callable[[Path], None]:
    return lambda w: os.mkfifo(w / name)


def symlink(name: str, target: str = "victim.txt") -> Callable[[Path], None]:
    def make(w: Path) -> None:
        (w / target).write_text("not calibctl's\n")
        (w / name).symlink_to(w / target)

    return make


def text(name: str, content: str | bytes) -> Callable[[Path], None]:
    def make(w: Path) -> None:
        path = w / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content if isinstance(content, bytes) else content.encode())

    return make


def folder(name: str, files: dict[str, bytes] | None = None) -> Callable[[Path], None]:
    def make(w: Path) -> None:
        (w / name).mkdir(parents=True, exist_ok=True)
        for file_name, data in (files or {}).items():
            (w / name / file_name).write_bytes(data)

    return make


def views(name: str, count: int = 3, rename: Callable[[int], bytes] | None = None) -> Callable[[Path], None]:
    """``count`` of the demo's rendered views copied into ``name`` (optionally under hostile byte names)."""

    def make(w: Path) -> None:
        dest = w / name
        dest.mkdir(parents=True, exist_ok=True)
        for i, src in enumerate(sorted((w / "demo" / "good-session").glob("view-*.png"))[:count]):
            target = os.path.join(os.fsencode(dest), rename(i)) if rename else os.fsencode(dest / src.name)
            shutil.copyfile(src, target)

    return make


def both(*steps: Callable[[Path], None]) -> Callable[[Path], None]:
    def make(w: Path) -> None:
        for step in steps:
            step(w)

    return make


def read_only_store(w: Path) -> None:
    (w / "store.db").chmod(0o444)
    w.chmod(0o555)


def read_only_file(w: Path) -> None:
    (w / "store.db").chmod(0o444)


def tiny_png(w: Path, name: str = "tiny/one.png", size: tuple[int, int] = (1, 1)) -> None:
    import cv2
    import numpy as np

    (w / name).parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(w / name), np.zeros((size[1], size[0]), np.uint8))


def exported(name: str, edit: Callable[[dict], None] | None = None) -> Callable[[Path], None]:
    """The demo camera's JSON export (optionally edited, not re-sealed) at ``name``."""

    def make(w: Path) -> None:
        calibctl(w, ["export", SERIAL, "-o", str(w / name)])
        if edit is not None:
            doc = json.loads((w / name).read_text())
            edit(doc)
            (w / name).write_text(json.dumps(doc))

    return make


def motions(name: str, mangle: Callable[[str], str] | None = None, rows: int = 40) -> Callable[[Path], None]:
    def make(w: Path) -> None:
        calibctl(w, ["synth-motions", str(w / name), "--rows", str(rows)])
        if mangle is not None:
            (w / name).write_text(mangle((w / name).read_text()))

    return make


def residuals(name: str, mangle: Callable[[str], str] | None = None) -> Callable[[Path], None]:
    def make(w: Path) -> None:
        calibctl(
            w, ["synth-residuals", str(w / name), "--fault", "focal", "--keyframes", "20", "--features", "10"]
        )
        if mangle is not None:
            (w / name).write_text(mangle((w / name).read_text()))

    return make


def second_data_line(value: str) -> Callable[[str], str]:
    """Replace the first field of the second data line by ``value``."""

    def mangle(body: str) -> str:
        lines = body.splitlines()
        data = [i for i, line in enumerate(lines) if line and not line.startswith("#")]
        row = lines[data[2]].split(",")
        row[1] = value
        lines[data[2]] = ",".join(row)
        return "\n".join(lines) + "\n"

    return mangle


_RIG_LOCK = threading.Lock()
_LIDAR_LOCK = threading.Lock()


def rig_source(w: Path) -> Path:
    """Once per sweep, beside the demo: a store ``rig.db`` whose rig R1 (CAM0 + CAM1, rendered 75 mm apart,
    calibrated and solved through the CLI on the demo's board) is exported as the bundle ``bundle/`` and
    its members as ``CAM0.json`` / ``CAM1.json``. The seal cases copy from it."""
    src = (w / "demo").resolve().parent / "rig"
    with _RIG_LOCK:
        if (src / "bundle" / "manifest.json").exists():
            return src
        src.mkdir(exist_ok=True)
        shutil.copyfile(w / "store.db", src / "rig.db")
        steps = [
            ["synth", str(src / "r"), "--rig", "2", "--views", "10", "--baseline-mm", "75", "--seed", "7"],
            *(
                ["calibrate", "--serial", c, "--board", BOARD, "--source", str(src / "r" / c)]
                for c in ("CAM0", "CAM1")
            ),
            ["rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1"],
            [
                "rig",
                "capture",
                "R1",
                "--board",
                BOARD,
                "--source",
                f"CAM0={src}/r/CAM0",
                "--source",
                f"CAM1={src}/r/CAM1",
            ],
            ["rig", "solve", "R1"],
            *(["export", c, "-o", str(src / f"{c}.json")] for c in ("CAM0", "CAM1")),
            ["rig", "export", "R1", "--format", "bundle", "-o", str(src / "bundle")],
        ]
        for args in steps:
            done = calibctl(src, args, db=src / "rig.db")
            if done.returncode != 0:
                raise RuntimeError(f"{' '.join(args[:3])}: {done.stderr[-300:]}")
        return src


def _lidar_solve(src: Path) -> None:
    """`lidar synth` (8 poses) and a store-free `lidar solve -o result.json` of it, in ``src``."""
    rendered = src / "set"
    done = calibctl(src, ["lidar", "synth", str(rendered), "--poses", "8", "--seed", "1"])
    if done.returncode == 0:
        box = json.loads((rendered / "truth.json").read_text())["box"]
        done = calibctl(
            src,
            ["lidar", "solve", "--images", str(rendered / "images"), "--scans", str(rendered / "scans")]
            + [
                "--camera-info",
                str(rendered / "camera_info.yaml"),
                "--box",
                box,
                "--cols",
                "5",
                "--rows",
                "7",
            ]
            + ["--square-mm", "95", "--backing-mm", "610,850", "--pattern-offset-mm", "2,0"]
            + ["-o", str(src / "result.json")],
        )
    if done.returncode != 0:
        raise RuntimeError(f"lidar synth / solve: {done.stderr[-300:]}")


def lidar_result(name: str, edit: Callable[[dict], None] | None = None) -> Callable[[Path], None]:
    """Once per sweep, a store-free `lidar solve -o` result of an 8-pose render (``lidar/result.json``);
    each case gets it at ``name``, ``edit``-ed (the content hash left as written)."""

    def make(w: Path) -> None:
        src = (w / "demo").resolve().parent / "lidar"
        with _LIDAR_LOCK:
            if not (src / "result.json").exists():
                src.mkdir(exist_ok=True)
                _lidar_solve(src)
        doc = json.loads((src / "result.json").read_text())
        if edit is not None:
            edit(doc)
        (w / name).write_text(json.dumps(doc))

    return make


def reseal(path: Path, body: str) -> None:
    """What a forger does without the key: write ``body``, recompute its ``file-sha256`` line and its entry
    in the bundle's manifest (checksums anyone can compute)."""
    import re

    kept = "".join(line for line in body.splitlines(keepends=True) if "calibctl file-sha256 " not in line)
    digest = hashlib.sha256(kept.encode()).hexdigest()
    body = re.sub(r"(calibctl file-sha256 )[0-9a-f]{64}", lambda m: m.group(1) + digest, body)
    path.write_text(body)
    manifest = path.parent / "manifest.json"
    doc = json.loads(manifest.read_text())
    for entry in doc["files"]:
        if entry["path"] == path.name:
            entry.update(sha256=hashlib.sha256(body.encode()).hexdigest(), bytes=len(body.encode()))
    manifest.write_text(json.dumps(doc, indent=2))


def bundle_copy(forge: Callable[[Path], None] | None = None) -> Callable[[Path], None]:
    """The rig source's bundle copied to ``b/`` (then ``forge(b)``) and its store to ``rig.db``: the store
    a `rig import` case imports into (its members are there, R1 registered; a forged version it took
    would be R1@2) and a `rig export --force` case exports from."""

    def make(w: Path) -> None:
        src = rig_source(w)
        shutil.copytree(src / "bundle", w / "b")
        shutil.copyfile(src / "rig.db", w / "rig.db")
        if forge is not None:
            forge(w / "b")

    return make


def rehashed_rig(edit: Callable[[dict], None]) -> Callable[[Path], None]:
    """rig.json at ``{w}/R1.json`` edited, its content hash recomputed and its signature dropped (no key)."""

    def forge(b: Path) -> None:
        doc = json.loads((b / "rig.json").read_text())
        edit(doc)
        doc.pop("signature", None)
        (b.parent / "R1.json").write_text(json.dumps(doc))
        code = (
            "import json,sys; from calibctl.artifacts.rig import RigCalibration as R; p=sys.argv[1]; "
            "d=json.load(open(p)); d['content_sha256']=R.model_validate(d).computed_sha256(); "
            "json.dump(d, open(p, 'w'))"
        )
        subprocess.run([sys.executable, "-c", code, str(b.parent / "R1.json")], env=_env(), check=True)

    return forge


def signed_forgery(name: str) -> Callable[[Path], None]:
    """The demo camera imported into a store with a key (``signed.db``, key ``k.pem``) and exported from it
    as ``signed.json`` (its signature carries the public key); ``name``: that export with fx + 1 px and its
    content hash recomputed, the signature kept (what a forger without the key can do)."""

    def make(w: Path) -> None:
        key = {"CALIBCTL_SIGNING_KEY": str(w / "k.pem")}
        steps = [
            (["keys", "init", "--key", str(w / "k.pem")], None, None),
            (["export", SERIAL, "-o", str(w / "plain.json")], None, None),
            (["import", str(w / "plain.json")], w / "signed.db", key),
            (["export", f"{SERIAL}@1", "-o", str(w / "signed.json")], w / "signed.db", key),
        ]
        for args, db, env in steps:
            done = calibctl(w, args, db=db, env=env)
            if done.returncode != 0:
                raise RuntimeError(f"{' '.join(args[:2])}: {done.stderr[-300:]}")
        code = (
            "import json,sys; from calibctl.artifacts.calibration import CalibrationArtifact as A; "
            "d=json.load(open(sys.argv[1])); d['camera_matrix'][0][0]+=1.0; "
            "d['content_sha256']=A.model_validate(d).computed_sha256(); json.dump(d, open(sys.argv[2], 'w'))"
        )
        subprocess.run(
            [sys.executable, "-c", code, str(w / "signed.json"), str(w / name)], env=_env(), check=True
        )

    return make


def foreign_sqlite(name: str, journal: str = "delete") -> Callable[[Path], None]:
    """Another application's SQLite database (one table of its own) at ``name``."""

    def make(w: Path) -> None:
        con = sqlite3.connect(w / name)
        con.execute(f"PRAGMA journal_mode = {journal}")
        con.execute("CREATE TABLE notes (body TEXT)")
        con.execute("INSERT INTO notes VALUES ('mine')")
        con.commit()
        con.close()

    return make


def calibctl(
    w: Path, args: list[str], db: Path | None = None, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "calibctl", "--db", f"sqlite:///{db or w / 'store.db'}", *args],
        cwd=w,
        env=_env(env),
        capture_output=True,
        text=True,
        timeout=CASE_TIMEOUT_S,
        check=False,
    )


def _env(extra: dict[str, str] | None = None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("CALIBCTL_")}
    env.update(
        {
            "PYTHONPATH": str(SOURCE[0]),
            "CALIBCTL_OPERATOR": "sweep",
            "CALIBCTL_STATION": "sweep",
            "COLUMNS": "120",
            **(extra or {}),
        }
    )
    return env


# ---- the cases
# ----------------------------------------------------------------------------------------------


def _cases() -> list[Case]:
    from hostile_cases import cases  # the list itself, by command group (benchmarks/ is on sys.path)

    return cases()


# ---- running and judging
# ------------------------------------------------------------------------------------


def _rows(db: Path) -> dict[str, int]:
    if not db.exists():
        return {}
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        names = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        return {n: con.execute(f'SELECT count(*) FROM "{n}"').fetchone()[0] for n in names}  # noqa: S608 - our names
    finally:
        con.close()


def _fingerprint(path: Path) -> str:
    try:
        st = path.lstat()
    except FileNotFoundError:
        return "absent"
    if stat.S_ISLNK(st.st_mode):
        return f"link:{os.readlink(path)}"
    if stat.S_ISREG(st.st_mode):
        return f"file:{stat.S_IMODE(st.st_mode):o}:{hashlib.sha256(path.read_bytes()).hexdigest()}"
    return f"type:{stat.S_IFMT(st.st_mode):o}"


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _run(case: Case, w: Path) -> tuple[int | None, str, str]:
    prefix = UNPRIVILEGED if case.unprivileged else []
    argv = [*prefix, sys.executable, "-m", "calibctl", "--db", f"sqlite:///{w / 'store.db'}", *case.args]
    argv = [a.replace("{w}", str(w)) for a in argv]
    # a shell's background job starts with SIGINT ignored, and an ignored signal stays ignored across exec:
    # give the command the default disposition, so that an interrupt case interrupts
    proc = subprocess.Popen(
        argv,
        cwd=w,
        env=_env(case.env),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        preexec_fn=_default_sigint,
    )  # noqa: PLW1509 - it only resets one signal
    if case.interrupt_s is not None:
        time.sleep(case.interrupt_s)
        proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=CASE_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        return None, out.decode(errors="replace"), err.decode(errors="replace")
    return proc.returncode, out.decode(errors="replace"), err.decode(errors="replace")


def judge(
    case: Case,
    code: int | None,
    out: str,
    err: str,
    before: dict[str, int],
    after: dict[str, int],
    changed: list[str],
    verified: bool,
) -> tuple[str, str]:
    """(category, why) for one case's outcome."""
    if code is None:
        return "crash", f"no answer within {CASE_TIMEOUT_S} s"
    if "Traceback" in err or code not in (0, 1, 2, 130):
        return "crash", f"exit {code}: {(err.strip().splitlines() or ['(no message)'])[-1][:160]}"
    if changed:
        return "lost", f"changed: {', '.join(changed)}"
    if any(after.get(t, 0) < n for t, n in before.items()) or not verified:
        return "lost", "rows disappeared" if verified else "db verify fails afterwards"
    grew = sorted(t for t in after if after[t] > before.get(t, 0) and t != "alembic_version")
    if case.expect == "refuse" and code != 0 and grew and (code == 2 or any("activation" in t for t in grew)):
        # exit 1 may store a rejected record by contract ("stored for the record, never active")
        return "stored", f"exit {code} but rows added to {', '.join(grew)}"
    if case.expect == "refuse" and code == 0:
        return "accepted", f"exit 0{' and stored ' + ', '.join(grew) if grew else ''}"
    if case.expect == "ok" and code != 0:
        return "refused", (err.strip().splitlines() or ["(no message)"])[0][:160]
    missing = [w for w in case.says if w not in out + err]
    if missing:
        return "misnamed", f"exit {code} without {missing[0]!r}: " + (err.strip() or out.strip())[:120]
    first = next((line for line in err.splitlines() if line.startswith("Error")), "")
    if case.expect == "refuse" and not first and code == 2:
        return "clean", "exit 2 (usage)"
    return "clean", first[:160] or f"exit {code}"


def run_case(case: Case, base: Path, root: Path) -> dict[str, object]:
    w = Path(tempfile.mkdtemp(prefix="case-", dir=root))
    shutil.copyfile(base / "store.db", w / "store.db")
    (w / "demo").symlink_to(base / "demo")  # read-only inputs (views); only the store is copied
    if (base / "demo" / "calibctl-images").exists():
        shutil.copytree(base / "demo" / "calibctl-images", w / "calibctl-images")
    if case.setup is not None:
        try:
            case.setup(w)
        except Exception as exc:  # noqa: BLE001 - the sweep's own fault, reported as such, not a finding
            return {
                "group": case.group,
                "case": case.name,
                "exit": None,
                "category": "setup",
                "why": repr(exc),
            }
    guarded = [*case.protect, "store.db"]
    prints = {p: _fingerprint(w / p) for p in guarded}
    before = _rows(w / "store.db")
    code, out, err = _run(case, w)
    w.chmod(0o755)
    if (w / "store.db").exists():
        (w / "store.db").chmod(0o644)
    changed = [p for p in guarded if p != "store.db" and _fingerprint(w / p) != prints[p]]
    after = _rows(w / "store.db")
    store_changed = _fingerprint(w / "store.db") != prints["store.db"]
    verified = calibctl(w, ["db", "verify"]).returncode == 0 if after and store_changed else True
    category, why = judge(case, code, out, err, before, after, changed, verified)
    shutil.rmtree(w, ignore_errors=True)
    return {"group": case.group, "case": case.name, "exit": code, "category": category, "why": why}


def make_base(root: Path) -> Path:
    base = root / "base"
    base.mkdir()
    done = subprocess.run(
        [sys.executable, "-m", "calibctl", "demo", "--out", str(base / "demo")],
        cwd=base,
        env=_env(),
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise SystemExit(f"demo failed: {done.stderr[-400:]}")
    shutil.copyfile(base / "demo" / "calibctl-demo.db", base / "store.db")
    return base


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", help="run only this command group")
    parser.add_argument("--name", help="run only the cases whose name holds this text")
    parser.add_argument("--json", type=Path, help="write every case's result here")
    parser.add_argument("--workers", type=int, default=2, help="cases run at once")
    parser.add_argument(
        "--source", type=Path, default=REPO, help="the calibctl tree to run (default: this one)"
    )
    options = parser.parse_args()
    SOURCE[0] = options.source.resolve()
    cases = [c for c in _cases() if options.only in (None, c.group) and (options.name or "") in c.name]
    root = Path(tempfile.mkdtemp(prefix="hostile-sweep-"))
    root.chmod(0o755)
    results = []
    try:
        base = make_base(root)
        with ThreadPoolExecutor(options.workers) as pool:  # each case is a process of its own
            for case, result in zip(cases, pool.map(lambda c: run_case(c, base, root), cases), strict=True):
                results.append(result)
                if result["category"] != "clean":
                    print(f"{result['category']:9} {case.group:16} {case.name}: {result['why']}", flush=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    table = Counter((r["group"], r["category"]) for r in results)
    groups = sorted({r["group"] for r in results})
    print(f"\n{len(results)} cases")
    print("| group | " + " | ".join(CATEGORIES) + " |")
    for g in groups:
        print(f"| {g} | " + " | ".join(str(table[(g, c)]) for c in CATEGORIES) + " |")
    totals = Counter(r["category"] for r in results)
    print("| all | " + " | ".join(str(totals[c]) for c in CATEGORIES) + " |")
    if options.json:
        options.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
