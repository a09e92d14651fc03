"""The cases of benchmarks/hostile_sweep.py, by command group (the sweep's categories, re-measured)."""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path

from hostile_sweep import (
    BOARD,
    SERIAL,
    Case,
    both,
    bundle_copy,
    calibctl,
    exported,
    fifo,
    folder,
    foreign_sqlite,
    lidar_result,
    motions,
    read_only_file,
    read_only_store,
    rehashed_rig,
    reseal,
    residuals,
    second_data_line,
    signed_forgery,
    symlink,
    text,
    tiny_png,
    views,
)

BAD_NUMBERS = ("nan", "inf", "-inf", "1e308")
BOX = "-1,-1,0,1,1,3"
DEEP_JSON = "[" * 200000 + "]" * 200000
YAML_BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
    for p, c in zip("abcdefgh", "bcdefghi", strict=True)
)

TIMESTAMPS_HEAD = "sync_index,cam_id,frame_index,frame_time\n"


def _two_folders(*extra: str, a: str = "{w}/v", b: str = "{w}/w") -> list[str]:
    """`rig solve-folders` of cameras A and B on a 9x6 25 mm chessboard, then ``extra``."""
    return ["rig", "solve-folders", "--source", f"A={a}", "--source", f"B={b}", "--cols", "9", "--rows", "6",
            "--square-mm", "25", *extra]  # fmt: skip


def _out_targets(group: str, argv: list[str], out_flag: str | None = "-o") -> list[Case]:
    """A writer aimed at a FIFO, a symlink, a dangling symlink and a folder, with --force: nothing
    replaced."""
    at = (lambda p: [out_flag, p]) if out_flag else (lambda p: [p])
    return [
        Case(
            group,
            f"{' '.join(argv[:2])} onto a FIFO --force",
            [*argv, *at("{w}/t"), "--force"],
            setup=fifo("t"),
            protect=["t"],
        ),
        Case(
            group,
            f"{' '.join(argv[:2])} onto a symlink --force",
            [*argv, *at("{w}/t"), "--force"],
            setup=symlink("t"),
            protect=["t", "victim.txt"],
        ),
        Case(
            group,
            f"{' '.join(argv[:2])} onto a dangling symlink",
            [*argv, *at("{w}/t"), "--force"],
            setup=lambda w: (w / "t").symlink_to(w / "nowhere"),
            protect=["t"],
        ),
        Case(
            group, f"{' '.join(argv[:2])} onto a folder", [*argv, *at("{w}/d"), "--force"], setup=folder("d")
        ),
    ]


def _capture() -> list[Case]:
    g = "capture"
    base = ["capture", "--serial", "HOSTILE-1", "--board", BOARD, "--source"]
    cases = [
        Case(g, "missing folder", [*base, "{w}/nope"]),
        Case(g, "empty folder", [*base, "{w}/empty"], setup=folder("empty")),
        Case(g, "text renamed .png", [*base, "{w}/f"], setup=folder("f", {"a.png": b"hello", "b.png": b""})),
        Case(g, "1x1 image", [*base, "{w}/tiny"], setup=tiny_png),
        Case(
            g, "non-UTF-8 names", [*base, "{w}/v"], setup=views("v", 3, lambda i: b"view-\xff\xfe%d.png" % i)
        ),
        Case(g, "ESC in names", [*base, "{w}/v"], setup=views("v", 3, lambda i: b"v\x1b[2J%d.png" % i)),
        Case(g, "FIFO among images", [*base, "{w}/v"], setup=both(views("v", 2), fifo("v/z.png"))),
        Case(
            g,
            "symlink loop among images",
            [*base, "{w}/v"],
            setup=both(views("v", 2), lambda w: (w / "v" / "loop.png").symlink_to(w / "v" / "loop.png")),
        ),
        Case(
            g,
            "unknown board",
            ["capture", "--serial", "HOSTILE-1", "--board", "nope", "--source", "{w}/v"],
            setup=views("v", 3),
        ),
        Case(
            g,
            "serial with a slash",
            ["capture", "--serial", "a/b", "--board", BOARD, "--source", "{w}/v"],
            setup=views("v", 3),
        ),
        Case(
            g,
            "serial with ESC",
            ["capture", "--serial", "a\x1b[2Jb", "--board", BOARD, "--source", "{w}/v"],
            setup=views("v", 3),
        ),
        Case(g, "--max-views 0", [*base, "{w}/v", "--max-views", "0"], setup=views("v", 3)),
        Case(g, "--max-views -1", [*base, "{w}/v", "--max-views", "-1"], setup=views("v", 3)),
        Case(g, "--max-views 10^30", [*base, "{w}/v", "--max-views", str(10**30)], setup=views("v", 3)),
        Case(g, "few views (gates fail)", [*base, "{w}/v"], setup=views("v", 3)),
        Case(g, "read-only store", [*base, "{w}/v"], setup=both(views("v", 3), read_only_store)),
        Case(
            g,
            "read-only store, unprivileged",
            [*base, "{w}/v"],
            setup=both(views("v", 3), read_only_store),
            unprivileged=True,
        ),
        Case(g, "source is a FIFO list file", [*base, "{w}/t"], setup=fifo("t")),
        Case(
            g,
            "calibrate on an empty folder",
            ["calibrate", "--serial", "H", "--board", BOARD, "--source", "{w}/e"],
            setup=folder("e"),
        ),
        Case(g, "prune on a read-only store", ["prune"], setup=read_only_store, unprivileged=True),
        *[
            Case(
                g,
                f"capture interrupted at {t} s",
                [*base, "{w}/demo/good-session"],
                expect="any",
                interrupt_s=t,
            )
            for t in (0.3, 0.8, 1.2)
        ],
    ]
    cases += [
        Case(g, f"--duration {v}", [*base, "{w}/v", "--duration", v], setup=views("v", 3))
        for v in BAD_NUMBERS
    ]
    return cases


def _synth() -> list[Case]:
    g = "synth"
    cases = [
        Case(g, "--views 0", ["synth", "{w}/s", "--views", "0"]),
        Case(g, "--views -3", ["synth", "{w}/s", "--views", "-3"]),
        Case(g, "--views 10^9", ["synth", "{w}/s", "--views", str(10**9)]),
        Case(g, "--size 0x0", ["synth", "{w}/s", "--size", "0x0"]),
        Case(g, "--size 100000x100000", ["synth", "{w}/s", "--size", "100000x100000"]),
        Case(g, "--size abc", ["synth", "{w}/s", "--size", "abc"]),
        Case(g, "--baseline-mm without --rig", ["synth", "{w}/s", "--baseline-mm", "75"]),
        Case(g, "--rig 99", ["synth", "{w}/s", "--rig", "99"]),
        Case(g, "out is a file", ["synth", "{w}/f"], setup=text("f", "mine"), protect=["f"]),
        Case(g, "out is a FIFO --force", ["synth", "{w}/t", "--force"], setup=fifo("t"), protect=["t"]),
        Case(
            g,
            "out is a symlink --force",
            ["synth", "{w}/t", "--force"],
            setup=symlink("t"),
            protect=["t", "victim.txt"],
        ),
        Case(
            g,
            "out holds a stranger's file --force",
            ["synth", "{w}/s", "--force"],
            expect="ok",
            setup=text("s/notes.txt", "keep me"),
            protect=["s/notes.txt"],
        ),
        Case(
            g,
            "synth-residuals --keyframes 10^7",
            ["synth-residuals", "{w}/r.csv", "--fault", "focal", "--keyframes", "10000000"],
        ),
        Case(g, "synth-residuals --fault bogus", ["synth-residuals", "{w}/r.csv", "--fault", "bogus"]),
        Case(g, "synth-motions --rows 10^9", ["synth-motions", "{w}/m.csv", "--rows", str(10**9)]),
        Case(g, "synth-motions --rows 0", ["synth-motions", "{w}/m.csv", "--rows", "0"]),
        Case(g, "lidar synth out is a FIFO", ["lidar", "synth", "{w}/t"], setup=fifo("t"), protect=["t"]),
    ]
    cases += [
        Case(
            g,
            f"synth-residuals --magnitude {v}",
            ["synth-residuals", "{w}/r.csv", "--fault", "focal", "--magnitude", v],
        )
        for v in BAD_NUMBERS
    ]
    cases += [
        Case(
            g,
            f"synth-residuals --drift-ppm {v}",
            ["synth-residuals", "{w}/r.csv", "--fault", "focal", "--drift-ppm", v],
        )
        for v in BAD_NUMBERS[:2]
    ]
    cases += [
        Case(g, f"synth-motions --time-offset-ms {v}", ["synth-motions", "{w}/m.csv", "--time-offset-ms", v])
        for v in BAD_NUMBERS
    ]
    cases += [
        Case(g, f"lidar synth --range-offset-mm {v}", ["lidar", "synth", "{w}/l", "--range-offset-mm", v])
        for v in BAD_NUMBERS[:2]
    ]
    cases += _out_targets(g, ["synth-motions"], out_flag=None)[:2]
    cases += _out_targets(g, ["synth-residuals", "--fault", "focal"], out_flag=None)[:2]
    return cases


def _solve_check() -> list[Case]:
    g = "solve/check/diff"
    return [
        Case(g, "solve unknown session", ["solve", "nope"]),
        Case(g, "solve unknown serial", ["solve", "--serial", "NOPE"]),
        Case(g, "solve --model bogus", ["solve", "--serial", SERIAL, "--model", "bogus"]),
        Case(
            g,
            "solve on a read-only store",
            ["solve", "--serial", SERIAL],
            setup=read_only_store,
            unprivileged=True,
        ),
        Case(
            g,
            "solve --report onto a FIFO",
            ["solve", "--serial", SERIAL, "--report", "{w}/t"],
            setup=fifo("t"),
            protect=["t"],
        ),
        Case(
            g,
            "solve --report onto a symlink",
            ["solve", "--serial", SERIAL, "--report", "{w}/t"],
            setup=symlink("t"),
            protect=["t", "victim.txt"],
        ),
        *[
            Case(g, f"solve interrupted at {t} s", ["solve", "--serial", SERIAL], expect="any", interrupt_s=t)
            for t in (0.3, 0.8, 1.2)
        ],
        Case(g, "check unknown serial", ["check", "NOPE", "--source", "{w}/v"], setup=views("v", 3)),
        Case(g, "check empty folder", ["check", SERIAL, "--source", "{w}/e"], setup=folder("e")),
        Case(g, "check from a FIFO list file", ["check", SERIAL, "--source", "{w}/t"], setup=fifo("t")),
        Case(g, "check 3 views", ["check", SERIAL, "--source", "{w}/v"], setup=views("v", 3)),
        Case(g, "check @99", ["check", f"{SERIAL}@99", "--source", "{w}/v"], setup=views("v", 3)),
        Case(
            g,
            "check non-UTF-8 names",
            ["check", SERIAL, "--source", "{w}/v"],
            setup=views("v", 3, lambda i: b"\xff%d.png" % i),
        ),
        Case(g, "diff unknown", ["diff", "NOPE@1", "NOPE@2"]),
        Case(g, "diff @0", ["diff", f"{SERIAL}@0", f"{SERIAL}@1"]),
        *[
            Case(g, f"diff --scale {v}", ["diff", f"{SERIAL}@1", f"{SERIAL}@1", "--scale", v])
            for v in (*BAD_NUMBERS, "0", "-1")
        ],
        *[
            Case(g, f"diff --range-m {v}", ["diff", f"{SERIAL}@1", f"{SERIAL}@1", "--range-m", v])
            for v in ("nan", "-1", "0")
        ],
    ]


def _records() -> list[Case]:
    g = "history/show/export"
    ok_reads = [
        ["history", SERIAL],
        ["show", SERIAL],
        ["export", SERIAL],
        ["lint", "--serial", SERIAL],
        ["db", "verify"],
        ["board", "list"],
    ]
    cases = [
        *[
            Case(
                g,
                f"{' '.join(a[:2])} on a read-only file",
                a,
                expect="ok",
                setup=read_only_file,
                unprivileged=True,
            )
            for a in ok_reads
        ],
        *[
            Case(
                g,
                f"{' '.join(a[:2])} in a read-only folder",
                a,
                expect="ok",
                setup=read_only_store,
                unprivileged=True,
            )
            for a in ok_reads[:3]
        ],
        Case(g, "show unknown", ["show", "NOPE"]),
        Case(g, "show CAM@x", ["show", f"{SERIAL}@x"]),
        Case(g, "show CAM@-1", ["show", f"{SERIAL}@-1"]),
        Case(g, "show CAM@10^20", ["show", f"{SERIAL}@{10**20}"]),
        Case(g, "history ESC serial", ["history", "A\x1b[2J"]),
        Case(g, "export --format bogus", ["export", SERIAL, "--format", "bogus"]),
        Case(
            g,
            "export onto an existing file",
            ["export", SERIAL, "-o", "{w}/f"],
            setup=text("f", "mine"),
            protect=["f"],
        ),
        Case(g, "export -o into a missing folder", ["export", SERIAL, "-o", "{w}/no/such/x.json"]),
        Case(
            g,
            "export -o read-only folder",
            ["export", SERIAL, "-o", "{w}/ro/x.json"],
            setup=lambda w: (w / "ro").mkdir(mode=0o555),
            unprivileged=True,
        ),
        *_out_targets(g, ["export", SERIAL]),
        *_out_targets(g, ["export", SERIAL, "--format", "ros"]),
        *_out_targets(g, ["report", SERIAL]),
        Case(g, "report unknown serial", ["report", "NOPE", "-o", "{w}/r.html"]),
        Case(g, "rollback to a missing version", ["rollback", SERIAL, "--to", "9", "--reason", "x"]),
        Case(g, "rollback --to -1", ["rollback", SERIAL, "--to", "-1", "--reason", "x"]),
        Case(g, "rollback --to 10^30", ["rollback", SERIAL, "--to", str(10**30), "--reason", "x"]),
        Case(g, "rollback 100k reason", ["rollback", SERIAL, "--to", "1", "--reason", "x" * 100000]),
        Case(g, "rollback empty reason", ["rollback", SERIAL, "--to", "1", "--reason", ""]),
        Case(
            g,
            "rollback on a read-only store",
            ["rollback", SERIAL, "--to", "1", "--reason", "x"],
            setup=read_only_store,
            unprivileged=True,
        ),
    ]
    return cases


def _imports() -> list[Case]:
    g = "import/lint"

    def doc_edit(key: str, value: object) -> Callable[[dict], None]:
        return lambda doc: doc.__setitem__(key, value)

    files = {
        "garbage": text("x.json", "not json"),
        "empty": text("x.json", ""),
        "truncated": text("x.json", '{"serial": "A'),
        "non-UTF-8": text("x.json", b"\xff\xfe{}"),
        "deep nesting": text("x.json", DEEP_JSON),
        "NaN literal": text("x.json", '{"rms_px": NaN}'),
        "1e400": text("x.json", '{"rms_px": 1e400}'),
        "YAML bomb": text("x.json", YAML_BOMB),
        "a folder": folder("x.json"),
        "a FIFO": fifo("x.json"),
        "hash mismatch": exported("x.json", doc_edit("rms_px", 0.01)),
        "schema_version 99": exported("x.json", doc_edit("schema_version", 99)),
        "fx edited": exported("x.json", lambda d: d["camera_matrix"][0].__setitem__(0, 900.0)),
    }
    cases = [
        Case(g, f"import {name}", ["import", "{w}/x.json"], setup=setup) for name, setup in files.items()
    ]
    cases += [
        Case(g, f"lint {name}", ["lint", "{w}/x.json"], setup=setup)
        for name, setup in files.items()
        if name != "a FIFO"
    ]
    cases += [
        Case(g, "import own export (no-op)", ["import", "{w}/x.json"], expect="ok", setup=exported("x.json")),
        Case(
            g,
            "import own export into a read-only store (a no-op)",
            ["import", "{w}/x.json"],
            expect="ok",
            setup=both(exported("x.json"), read_only_store),
            unprivileged=True,
        ),
        Case(g, "lint --serial unknown", ["lint", "--serial", "NOPE"]),
        Case(g, "lint missing file", ["lint", "{w}/nope.json"]),
    ]
    return cases


def _diagnostics() -> list[Case]:
    g = "triage/gauge/handeye"
    cases = []
    for cmd in ("triage", "gauge", "handeye"):
        extra = ["--from", "base", "--to", "cam"] if cmd == "handeye" else []
        for name, setup in (
            ("missing", None),
            ("empty", text("x.csv", "")),
            ("garbage", text("x.csv", "a,b\n1,2\n")),
            ("binary", text("x.csv", bytes(range(256)) * 8)),
            ("a folder", folder("x.csv")),
        ):
            cases.append(Case(g, f"{cmd} {name}", [cmd, "{w}/x.csv", *extra], setup=setup))
    for v in ("nan", "inf", "1e308", "abc"):
        cases.append(
            Case(
                g,
                f"triage {v} residual",
                ["triage", "{w}/x.csv"],
                setup=residuals("x.csv", second_data_line(v)),
            )
        )
        cases.append(
            Case(
                g,
                f"handeye {v} in a pose",
                ["handeye", "{w}/x.csv", "--from", "base", "--to", "cam"],
                setup=motions("x.csv", second_data_line(v)),
            )
        )
    cases += [
        Case(
            g,
            "handeye 3 rows",
            ["handeye", "{w}/x.csv", "--from", "base", "--to", "cam"],
            setup=motions("x.csv", rows=3),
        ),
        Case(
            g,
            "handeye --method bogus",
            ["handeye", "{w}/x.csv", "--from", "b", "--to", "c", "--method", "x"],
            setup=motions("x.csv"),
        ),
        *_out_targets(g, ["handeye", "{w}/x.csv", "--from", "base", "--to", "cam"])[:2],
        *[
            Case(g, f"{cmd} a FIFO", [cmd, "{w}/t", *extra], setup=fifo("t"))
            for cmd, extra in (
                ("triage", []),
                ("gauge", []),
                ("handeye", ["--from", "base", "--to", "cam"]),
                ("timeoffset", ["{w}/t"]),
            )
        ],
        Case(g, "timeoffset missing", ["timeoffset", "{w}/g.csv", "{w}/c.csv"]),
        Case(g, "timeoffset garbage", ["timeoffset", "{w}/g.csv", "{w}/g.csv"], setup=text("g.csv", "x\n")),
    ]
    return cases


def _admin() -> list[Case]:
    g = "board/rig/lidar"
    add = [
        "board",
        "add",
        "B2",
        "--kind",
        "chessboard",
        "--cols",
        "9",
        "--rows",
        "6",
        "--uncertainty-mm",
        "0.02",
        "--instrument",
        "calipers",
        "--measured-by",
        "qa",
        "--measured-on",
        "2026-03-11",
    ]
    cases = [
        Case(g, f"board add --square-mm {v}", [*add, "--square-mm", v]) for v in (*BAD_NUMBERS, "0", "-1")
    ]
    cases += [
        Case(
            g, "board add --cols 0", [*add[:5], "--cols", "0", "--rows", "6", *add[9:], "--square-mm", "25"]
        ),
        Case(
            g,
            "board add --cols 10^9",
            [*add[:5], "--cols", str(10**9), "--rows", "6", *add[9:], "--square-mm", "25"],
        ),
        Case(g, "board add bad date", [*add[:-1], "yesterday", "--square-mm", "25"]),
        Case(
            g,
            "board add a second time (a new revision)",
            ["board", "add", BOARD, *add[3:], "--square-mm", "25"],
            expect="ok",
        ),
        Case(
            g,
            "board add --evidence a FIFO",
            [*add, "--square-mm", "25", "--evidence", "{w}/t"],
            setup=fifo("t"),
        ),
        Case(
            g,
            "board add with the signing key a FIFO",
            [*add, "--square-mm", "25"],
            setup=fifo("k.pem"),
            env={"CALIBCTL_SIGNING_KEY": "k.pem"},
        ),
        Case(
            g,
            "lidar solve scans hold a FIFO",
            [
                "lidar",
                "solve",
                "--images",
                "{w}/v",
                "--scans",
                "{w}/s",
                "--cols",
                "9",
                "--rows",
                "6",
                "--square-mm",
                "25",
                "--box",
                BOX,
                "--backing-mm",
                "300,220",
                "--serial",
                SERIAL,
            ],
            setup=both(views("v", 3), folder("s"), fifo("s/000.npy")),
        ),
        Case(
            g,
            "rig capture (unknown rig) from a FIFO list",
            ["rig", "capture", "R9", "--board", BOARD, "--source", "A={w}/t", "--source", "B={w}/t"],
            setup=fifo("t"),
        ),
        Case(g, "board show unknown", ["board", "show", "nope"]),
        Case(
            g,
            "rig solve-folders same folder twice",
            [
                "rig",
                "solve-folders",
                "--source",
                "A={w}/demo/good-session",
                "--source",
                "B={w}/demo/good-session",
                "--cols",
                "9",
                "--rows",
                "6",
                "--square-mm",
                "25",
            ],
        ),
        Case(
            g,
            "rig solve-folders missing",
            [
                "rig",
                "solve-folders",
                "--source",
                "A={w}/no",
                "--source",
                "B={w}/no2",
                "--cols",
                "9",
                "--rows",
                "6",
                "--square-mm",
                "25",
            ],
        ),
        *[
            Case(
                g,
                f"rig solve-folders --square-mm {v}",
                [
                    "rig",
                    "solve-folders",
                    "--source",
                    "A={w}/v",
                    "--source",
                    "B={w}/v",
                    "--cols",
                    "9",
                    "--rows",
                    "6",
                    "--square-mm",
                    v,
                ],
                setup=views("v", 3),
            )
            for v in ("nan", "inf")
        ],
        Case(
            g,
            "rig solve-folders --min-shared-views -1",
            [
                "rig",
                "solve-folders",
                "--source",
                "A={w}/v",
                "--source",
                "B={w}/w",
                "--cols",
                "9",
                "--rows",
                "6",
                "--square-mm",
                "25",
                "--min-shared-views",
                "-1",
            ],
            setup=both(views("v", 3), views("w", 3)),
        ),
        *[
            Case(
                g,
                f"rig solve-folders --timestamps {what}",
                _two_folders("--timestamps", "{w}/ts.csv"),
                setup=both(views("v", 3), views("w", 3), text("ts.csv", TIMESTAMPS_HEAD + rows)),
                says=says,
            )
            for what, rows, says in (
                (
                    "naming a camera that does not exist",
                    "0,A,0,1.0\n0,B,0,1.001\n0,C,0,1.002\n",
                    ("names camera C",),
                ),
                ("with duplicated times", "0,A,0,1.0\n1,A,1,1.0\n0,B,0,1.001\n", ("same time",)),
                ("with frames past the end", "0,A,0,1.0\n0,B,0,1.001\n9,A,9,2.0\n", ("frames past the end",)),
                ("missing a camera", "0,A,0,1.0\n", ("lists no frame of camera B",)),
            )  # fmt: skip
        ],
        Case(
            g,
            "rig solve-folders undecodable video",
            _two_folders(a="{w}/a.mp4", b="{w}/a.mp4"),
            setup=text("a.mp4", b"\x00\x00\x00\x18ftypmp42 not a video" * 20),
            says=("cannot decode the video",),
        ),
        Case(
            g,
            "rig solve-folders --frame-shift not a number",
            _two_folders("--frame-shift", "B=half"),
            setup=both(views("v", 3), views("w", 3)),
            says=("--frame-shift B=half",),
        ),
        Case(
            g,
            "rig solve-folders --exposure-offset not a number",
            _two_folders("--exposure-offset", "B=late"),
            setup=both(views("v", 3), views("w", 3)),
            says=("--exposure-offset B=late",),
        ),
        Case(g, "rig add unknown member", ["rig", "add", "R1", "--camera", "NOPE", "--camera", "NOPE2"]),
        Case(g, "rig solve unknown", ["rig", "solve", "R9"]),
        Case(g, "rig show unknown", ["rig", "show", "R9"]),
        Case(g, "rig history unknown", ["rig", "history", "R9"]),
        Case(g, "rig rollback unknown", ["rig", "rollback", "R9", "--to", "1", "--reason", "x"]),
        Case(g, "rig lint unknown", ["rig", "lint", "R9"]),
        Case(
            g,
            "rig export unknown -o FIFO",
            ["rig", "export", "R9", "-o", "{w}/t", "--force"],
            setup=fifo("t"),
            protect=["t"],
        ),
        Case(
            g,
            "rig capture missing folders",
            ["rig", "capture", "R9", "--board", BOARD, "--source", "A={w}/no"],
        ),
        Case(
            g,
            "lidar solve missing",
            [
                "lidar",
                "solve",
                "--images",
                "{w}/no",
                "--scans",
                "{w}/no2",
                "--cols",
                "9",
                "--rows",
                "6",
                "--square-mm",
                "25",
                "--box",
                BOX,
                "--backing-mm",
                "300,220",
                "--serial",
                SERIAL,
            ],
        ),
        Case(
            g,
            "lidar solve empty folders",
            [
                "lidar",
                "solve",
                "--images",
                "{w}/e",
                "--scans",
                "{w}/e",
                "--cols",
                "9",
                "--rows",
                "6",
                "--square-mm",
                "25",
                "--box",
                BOX,
                "--backing-mm",
                "300,220",
                "--serial",
                SERIAL,
            ],
            setup=folder("e"),
        ),
    ]
    return cases


def _store() -> list[Case]:
    g = "db/keys/fleet/station"
    station = ["station", "--board", BOARD, "--source-template", "{w}/{serial}"]
    cases = [
        Case(g, "db verify --since garbage", ["db", "verify", "--since", "HEAD"]),
        Case(g, "--db is a folder", ["--db", "sqlite:///{w}", "history", SERIAL]),
        Case(
            g,
            "--db is a text file",
            ["--db", "sqlite:///{w}/t.db", "history", SERIAL],
            setup=text("t.db", "hello"),
            protect=["t.db"],
        ),
        Case(
            g, "--db is an empty file", ["--db", "sqlite:///{w}/t.db", "db", "verify"], setup=text("t.db", "")
        ),
        Case(
            g,
            "db upgrade on a text file",
            ["--db", "sqlite:///{w}/t.db", "db", "upgrade"],
            setup=text("t.db", "hello"),
            protect=["t.db"],
        ),
        Case(
            g,
            "--db postgres on a closed port",
            ["--db", "postgresql://x@127.0.0.1:9/none", "history", SERIAL],
        ),
        Case(g, "--station-config missing", ["--station-config", "{w}/no.yaml", "history", SERIAL]),
        Case(
            g,
            "station file YAML bomb",
            ["--station-config", "{w}/s.yaml", "history", SERIAL],
            setup=text("s.yaml", YAML_BOMB),
        ),
        Case(
            g,
            "station file min_views 1e21",
            ["--station-config", "{w}/s.yaml", "history", SERIAL],
            setup=text("s.yaml", "gates:\n  min_views: 1000000000000000000000\n"),
        ),
        Case(g, "CALIBCTL_JOBS=nan", ["history", SERIAL], env={"CALIBCTL_JOBS": "nan"}),
        Case(
            g,
            "keys init onto a FIFO",
            ["keys", "init", "--key", "{w}/t", "--force"],
            setup=fifo("t"),
            protect=["t"],
        ),
        Case(
            g,
            "keys init onto a symlink",
            ["keys", "init", "--key", "{w}/t", "--force"],
            setup=symlink("t"),
            protect=["t", "victim.txt"],
        ),
        Case(g, "keys init in a missing folder", ["keys", "init", "--key", "{w}/no/k.pem"]),
        Case(g, "keys export-public missing key", ["keys", "export-public", "--key", "{w}/no.pem"]),
        Case(
            g,
            "signing key is a FIFO (a read needs no key)",
            ["history", SERIAL],
            expect="ok",
            setup=fifo("k.pem"),
            env={"CALIBCTL_SIGNING_KEY": "k.pem"},
        ),
        Case(
            g, "keys export-public --key a FIFO", ["keys", "export-public", "--key", "{w}/t"], setup=fifo("t")
        ),
        Case(g, "fleet ingest a FIFO", ["fleet", "ingest", "{w}/t"], setup=fifo("t")),
        Case(g, "fleet assign unknown robot", ["fleet", "assign", "R2D2", f"{SERIAL}@1", "--reason", "x"]),
        Case(
            g, "fleet ingest garbage", ["fleet", "ingest", "{w}/h.jsonl"], setup=text("h.jsonl", "garbage\n")
        ),
        Case(
            g,
            "fleet ingest non-UTF-8",
            ["fleet", "ingest", "{w}/h.jsonl"],
            setup=text("h.jsonl", b"\xff\xfe\n"),
        ),
        Case(
            g,
            "fleet ingest NaN",
            ["fleet", "ingest", "{w}/h.jsonl"],
            setup=text("h.jsonl", '{"rms_px": NaN}\n'),
        ),
        Case(g, "fleet trends unknown", ["fleet", "trends", "NOPE"]),
        Case(g, "fleet add ESC name", ["fleet", "add", "r\x1b[2J", "--serial", SERIAL]),
        Case(
            g,
            "station --serials missing file",
            [*station, "--serials", "{w}/no.txt"],
        ),
        Case(
            g,
            "station --serials a FIFO",
            [*station, "--serials", "{w}/t"],
            setup=fifo("t"),
        ),
        Case(
            g,
            "station --watch --views 0",
            [*station, "--watch", "--views", "0"],
        ),
        Case(
            g,
            "station --views without --watch",
            [*station, "--views", "5"],
        ),
        Case(
            g,
            "station --watch --settle-s -1",
            [*station, "--watch", "--views", "5", "--settle-s", "-1"],
        ),
        Case(
            g,
            "station --watch --unit-timeout-s nan",
            [*station, "--watch", "--views", "5", "--unit-timeout-s", "nan"],
        ),
        Case(
            g,
            "station --watch --done-file ../x",
            [*station, "--watch", "--done-file", "../x"],
        ),
        Case(g, "station --camera a folder", ["station", "--board", BOARD, "--camera", "{w}"]),
        Case(g, "station --camera empty", ["station", "--board", BOARD, "--camera", ""]),
        Case(g, "station --camera ESC", ["station", "--board", BOARD, "--camera", "/dev/video0\x1b[2J"]),
        Case(
            g,
            "station --camera and --source-template",
            ["station", "--board", BOARD, "--camera", "/dev/video987", "--source-template", "{w}/{serial}"],
        ),
        Case(
            g,
            "station --camera --watch",
            ["station", "--board", BOARD, "--camera", "/dev/video987", "--watch", "--views", "5"],
        ),
        Case(
            g,
            "station --camera --max-views 0",
            ["station", "--board", BOARD, "--camera", "/dev/video987", "--max-views", "0"],
        ),
        Case(
            g,
            "station --camera --duration nan",
            ["station", "--board", BOARD, "--camera", "/dev/video987", "--duration", "nan"],
        ),
        Case(
            g,
            "station --max-views without --camera",
            [*station, "--max-views", "5"],
        ),
        Case(
            g,
            "station --camera absent, no serials",
            ["station", "--board", BOARD, "--camera", "/dev/video987"],
            expect="ok",
        ),
        Case(
            g,
            "station set-aside, no spool",
            ["station", "set-aside", "1", "--reason", "x", "--spool", "{w}/no-spool.sqlite"],
        ),
        Case(g, "station set-aside not a number", ["station", "set-aside", "one", "--reason", "x"]),
        Case(g, "station set-aside empty reason", ["station", "set-aside", "1", "--reason", ""]),
        Case(g, "station set-aside ESC reason", ["station", "set-aside", "1", "--reason", "x\x1b[2J"]),
        Case(
            g,
            "station set-aside --spool a FIFO",
            ["station", "set-aside", "1", "--reason", "x", "--spool", "{w}/t"],
            setup=fifo("t"),
            protect=["t"],
        ),
        Case(
            g,
            "station set-aside --spool not ours",
            ["station", "set-aside", "1", "--reason", "x", "--spool", "{w}/f"],
            setup=text("f", "mine"),
            protect=["f"],
        ),
        Case(g, "demo --out a file", ["demo", "--out", "{w}/f"], setup=text("f", "mine"), protect=["f"]),
        Case(g, "demo --out a FIFO", ["demo", "--out", "{w}/t"], setup=fifo("t"), protect=["t"]),
    ]
    return cases


def _fx_plus_one(b: Path) -> None:
    body = (b / "cam1.yaml").read_text()
    m = re.search(r"camera_matrix:\n  rows: 3\n  cols: 3\n  data: \[([-0-9.e+]+)", body)
    if m is None:
        raise RuntimeError("no camera_matrix in cam1.yaml")
    reseal(b / "cam1.yaml", body[: m.start(1)] + repr(float(m.group(1)) + 1.0) + body[m.end(1) :])


def _swap_cameras(b: Path) -> None:
    left, right = (b / "cam0.yaml").read_text(), (b / "cam1.yaml").read_text()
    reseal(b / "cam0.yaml", right)
    reseal(b / "cam1.yaml", left)


def _edge_10mm(doc: dict) -> None:
    doc["edges"][0]["T_parent_child"][0][3] -= 0.010


def _member_fx(doc: dict) -> None:
    doc["members"][1]["camera_matrix"][0][0] += 5.0


def _lidar_10mm(doc: dict) -> None:
    t = doc["transform"]
    t["matrix"][0][3] += 0.01
    t["translation_m"][0] += 0.01
    t["T_cam_lidar"][0][3] -= 0.01


def _lidar_rehashed(doc: dict) -> None:
    """translation_m moved alone and the content hash recomputed (RFC 8785, no key needed)."""
    from calibctl.workflows.exports import sealed_result

    doc["transform"]["translation_m"][0] += 0.01
    doc["content_sha256"] = sealed_result.content_sha256(doc)


def _notes(b: Path) -> None:
    (b / "notes.txt").write_text("mine\n")


def _link(b: Path) -> None:
    (b.parent / "victim.txt").write_text("not calibctl's\n")
    (b / "tf_static.yaml").unlink()
    (b / "tf_static.yaml").symlink_to(b.parent / "victim.txt")


def _unsigned_ros_export(w: Path) -> None:
    """The demo camera's ROS export (the demo store has no key), a trusted-keys folder with a stranger's
    key."""
    (w / "keys").mkdir()
    calibctl(w, ["export", SERIAL, "--format", "ros", "-o", str(w / "c.yaml")])
    calibctl(w, ["keys", "init", "--key", str(w / "k.pem")])
    calibctl(w, ["keys", "export-public", "--key", str(w / "k.pem"), "-o", str(w / "keys" / "k.pem")])


def _seal() -> list[Case]:
    """What the robot loads is what was signed: forged bundles (no key, checksums recomputed), a rig.json
    re-hashed without its signature, another application's database, a bundle folder holding a user's
    files; each must be refused with nothing stored or changed."""
    g = "seal"
    manifest = "{w}/b/manifest.json"
    forged = {
        "fx +1 px, checksums recomputed": _fx_plus_one,
        "cam0/cam1 swapped, manifest fixed": _swap_cameras,
    }
    cases = [Case(g, f"lint bundle {n}", ["lint", manifest], setup=bundle_copy(f)) for n, f in forged.items()]
    into = ["--db", "sqlite:///{w}/rig.db", "rig", "import"]  # the rig's own store: members there
    cases += [
        Case(g, f"rig import bundle {n}", [*into, "{w}/b"], setup=bundle_copy(f), protect=["rig.db"])
        for n, f in forged.items()
    ]
    rehashed = {"edge +10 mm": _edge_10mm, "member fx +5 px": _member_fx}
    cases += [
        Case(
            g,
            f"rig import rig.json {n}, re-hashed, unsigned",
            [*into, "{w}/R1.json"],
            setup=bundle_copy(rehashed_rig(e)),
            protect=["rig.db"],
        )
        for n, e in rehashed.items()
    ]
    cases += [
        Case(g, "lint honest bundle", ["lint", manifest], expect="ok", setup=bundle_copy()),
        Case(
            g, "rig import honest bundle (already stored)", [*into, "{w}/b"], expect="ok", setup=bundle_copy()
        ),
        Case(
            g,
            "lint --require-signature on an unsigned store's ros export",
            ["lint", "{w}/c.yaml", "--require-signature", "--trusted-keys", "{w}/keys"],
            setup=_unsigned_ros_export,
        ),
    ]
    edited = "a signed export edited (fx +1 px, content hash recomputed, signature kept)"
    cases += [
        Case(
            g,
            f"import {edited} into a store without keys",
            ["import", "{w}/forged.json"],
            setup=signed_forgery("forged.json"),
            protect=["store.db"],
            says=("edited after signing",),
        ),
        Case(
            g,
            f"lint {edited}, no keys",
            ["lint", "{w}/forged.json"],
            setup=signed_forgery("forged.json"),
            says=("edited after signing",),
        ),
        Case(
            g,
            "import an honest export signed by an untrusted key into a store without keys",
            ["import", "{w}/signed.json"],
            expect="ok",
            setup=signed_forgery("forged.json"),
        ),
    ]
    lidar = {
        "translation +10 mm, every derived number too": (_lidar_10mm, "content hash does not match"),
        "translation_m +10 mm alone, re-hashed": (_lidar_rehashed, "are not transform.matrix's"),
    }
    cases += [
        Case(
            g,
            f"lint a store-free lidar result, {n}",
            ["lint", "{w}/r.json"],
            setup=lidar_result("r.json", e),
            says=(w,),
        )
        for n, (e, w) in lidar.items()
    ]
    cases.append(
        Case(
            g,
            "lidar synth --serial of a camera the store does not hold",
            ["lidar", "synth", "{w}/s", "--serial", "NOPE"],
            says=("NOPE",),
        )
    )
    cases.append(
        Case(
            g,
            "lint a store-free lidar result, honest",
            ["lint", "{w}/r.json"],
            expect="ok",
            setup=lidar_result("r.json"),
        )
    )
    force = ["--db", "sqlite:///{w}/rig.db", "rig", "export", "R1", "--format", "bundle", "-o", "{w}/b"]
    intruders = {
        "holding notes.txt": (_notes, ["b/notes.txt", "b/manifest.json"]),
        "whose tf_static.yaml is a symlink": (_link, ["b/tf_static.yaml", "victim.txt"]),
    }
    cases += [
        Case(g, f"rig export --force onto a bundle {n}", [*force, "--force"], setup=bundle_copy(f), protect=p)
        for n, (f, p) in intruders.items()
    ]
    cases += [
        Case(
            g,
            f"--db another application's SQLite ({journal} journal): {' '.join(args)}",
            ["--db", "sqlite:///{w}/app.db", *args],
            setup=both(foreign_sqlite("app.db", journal), exported("x.json")),
            protect=["app.db"],
        )
        for journal in ("delete", "wal")
        for args in (["history", SERIAL], ["db", "upgrade"], ["import", "{w}/x.json"])
    ]
    return cases


LIDAR_BOX = "0.8,-2.5,-1.2,4.5,2.5,1.2"  # `calibctl lidar synth`'s station box
LIDAR_BOARD = ["--cols", "5", "--rows", "7", "--square-mm", "95", "--backing-mm", "610,850"]


def lidar_set(w: Path) -> None:
    """An 8-pose `calibctl lidar synth` set at {w}/ls (a 5x7 board of 95 mm squares on 610 x 850 mm)."""
    calibctl(w, ["lidar", "synth", str(w / "ls"), "--poses", "8"])


def lidar_edit(edit: Callable[[Path], None]) -> Callable[[Path], None]:
    return both(lidar_set, edit)


def _replace_line(path: Path, start: str, line: str) -> None:
    text_ = path.read_text()
    old = next(x for x in text_.splitlines() if x.startswith(start))
    path.write_text(text_.replace(old, line))


def _nan_sweep(w: Path) -> None:
    scan = w / "ls" / "scans" / "pose1.pcd"
    header, _, body = scan.read_text().partition("DATA ascii\n")
    scan.write_text(header + "DATA ascii\n" + "nan nan nan 0 0\n" * len(body.splitlines()))


def _special_scan(make: Callable[[Path], None]) -> Callable[[Path], None]:
    def edit(w: Path) -> None:
        (w / "ls" / "scans" / "pose1.pcd").unlink()
        make(w / "ls" / "scans" / "pose1.pcd")

    return edit


def _lidar(*extra: str) -> list[str]:
    return [
        "lidar",
        "solve",
        "--images",
        "{w}/ls/images",
        "--scans",
        "{w}/ls/scans",
        "--box",
        LIDAR_BOX,
        *(extra if "--camera-info" in extra else ["--camera-info", "{w}/ls/camera_info.yaml", *extra]),
        "--pattern-offset-mm",
        "2,0",
    ]


def _rig_render(w: Path) -> None:
    calibctl(w, ["synth", str(w / "rig"), "--rig", "2", "--views", "8", "--baseline-mm", "75", "--seed", "7"])


def _messages() -> list[Case]:
    """Messages that used to blame the wrong thing: refused or warned, and ``says`` holds the words that name
    the real mistake."""
    g = "messages"
    board_9x6 = ["--cols", "9", "--rows", "6", "--square-mm", "50", "--backing-mm", "610,850"]
    square = [a if a != "95" else "100" for a in LIDAR_BOARD]
    rig = [
        "rig",
        "solve-folders",
        "--source",
        "CAM0={w}/rig/CAM0",
        "--source",
        "CAM1={w}/rig/CAM1",
        "--rows",
        "6",
    ]
    return [
        Case(
            g,
            "lidar camera_info K all zeros",
            _lidar(*LIDAR_BOARD),
            setup=lidar_edit(
                lambda w: _replace_line(w / "ls" / "camera_info.yaml", "K:", "K: [0, 0, 0, 0, 0, 0, 0, 0, 0]")
            ),
            says=("K is no camera matrix", "not calibrated"),
        ),
        Case(
            g,
            "lidar --square-mm 100 on a 95 mm board",
            _lidar(*square),
            setup=lidar_set,
            says=("squares look 9",),
        ),
        Case(
            g,
            "lidar pinhole images declared fisheye",
            _lidar(*LIDAR_BOARD),
            setup=lidar_edit(
                lambda w: (
                    _replace_line(
                        w / "ls" / "camera_info.yaml", "distortion_model", "distortion_model: equidistant"
                    ),
                    _replace_line(w / "ls" / "camera_info.yaml", "D:", "D: [0, 0, 0, 0]"),
                )
            ),
            says=("do not match that lens or its model",),
        ),
        Case(
            g,
            "lidar 9x6 given for the 5x7 set",
            _lidar(*board_9x6),
            setup=lidar_set,
            says=("chessboard is visible in",),
        ),
        Case(
            g,
            "lidar all-NaN sweep",
            _lidar(*LIDAR_BOARD),
            "any",
            setup=lidar_edit(_nan_sweep),
            says=("non-finite",),
        ),
        *[
            Case(
                g,
                f"lidar scan pose1.pcd is {kind}",
                _lidar(*LIDAR_BOARD),
                setup=lidar_edit(_special_scan(make)),
                says=("not a regular file",),
            )
            for kind, make in (
                ("a FIFO", os.mkfifo),
                ("a folder", lambda p: p.mkdir()),
                ("a symlink loop", lambda p: p.symlink_to(p)),
            )
        ],
        Case(
            g,
            "lidar --folds 100 on 8 poses",
            _lidar(*LIDAR_BOARD, "--folds", "100"),
            "ok",
            setup=lidar_set,
            says=("8-fold (leave-one-out)",),
        ),
        Case(
            g,
            "lidar --lidar-frame 'bad name!' --tf-static",
            _lidar(*LIDAR_BOARD, "--lidar-frame", "bad name!", "--tf-static", "{w}/tf.yaml"),
            setup=lidar_set,
            protect=["tf.yaml"],
            says=("not a legal ROS frame name",),
        ),
        Case(g, "diff CAM@x", ["diff", f"{SERIAL}@x", SERIAL], says=("is not a whole number",)),
        Case(
            g,
            "station serial with escape sequences",
            ["station", "--board", BOARD, "--serials", "{w}/lot.txt", "--source-template", "{w}/{serial}"],
            "ok",
            setup=text("lot.txt", "CAM\x1b[2J\x1b]0;x\x07-1\n"),
            says=("\\x1b[2J", "control characters"),
        ),
        Case(
            g,
            "rig solve-folders --cols 8 on 9x6 photos",
            [*rig, "--cols", "8", "--square-mm", "25"],
            setup=_rig_render,
            says=("9x6",),
        ),
        Case(
            g,
            "rig solve-folders --square-mm 2.5",
            [*rig, "--cols", "9", "--square-mm", "2.5"],
            "ok",
            setup=_rig_render,
            says=("square-size", "outside the 5-300 mm"),
        ),
    ]


def imu_recording(w: Path) -> None:
    """A 3 s `calibctl imu synth` recording at {w}/rec rendered through the demo camera (corner files)."""
    calibctl(w, ["imu", "synth", str(w / "rec"), "--serial", SERIAL, "--duration-s", "3"])


def _imu_csv(edit: Callable[[list[str]], list[str]], name: str = "imu0/data.csv") -> Callable[[Path], None]:
    def make(w: Path) -> None:
        imu_recording(w)
        path = w / "rec" / name
        path.write_text("\n".join(edit(path.read_text().splitlines())) + "\n")

    return make


def _scaled(cols: slice, factor: float) -> Callable[[list[str]], list[str]]:
    def edit(lines: list[str]) -> list[str]:
        out = [lines[0]]
        for line in lines[1:]:
            c = line.split(",")
            c[cols] = [f"{float(v) * factor:.6f}" for v in c[cols]]
            out.append(",".join(c))
        return out

    return edit


def _stamp_listed_twice(w: Path) -> None:
    imu_recording(w)
    stamps = sorted(p.stem for p in (w / "rec" / "cam0").glob("*.csv"))
    listing = ["#timestamp [ns],filename"] + [f"{s},{s}.png" for s in [stamps[0], *stamps[:3]]]
    (w / "rec" / "cam0" / "data.csv").write_text("\n".join(listing) + "\n")


def _imu_only_bag(w: Path) -> None:
    """A ROS 2 bag holding the recording's IMU topic /imu0 alone (the sweep needs the `bags` extra)."""
    import numpy as np
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    imu_recording(w)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    with Writer(w / "bag", version=9) as bag:
        imu_c = bag.add_connection("/imu0", "sensor_msgs/msg/Imu", typestore=ts)
        for line in (w / "rec" / "imu0" / "data.csv").read_text().splitlines()[1:]:
            c = line.split(",")
            ns, v = int(c[0]), [float(x) for x in c[1:]]
            msg = T["sensor_msgs/msg/Imu"](
                header=T["std_msgs/msg/Header"](
                    stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                    frame_id="imu",
                ),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=T["geometry_msgs/msg/Vector3"](x=v[0], y=v[1], z=v[2]),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=T["geometry_msgs/msg/Vector3"](x=v[3], y=v[4], z=v[5]),
                linear_acceleration_covariance=np.zeros(9),
            )
            bag.write(imu_c, ns, ts.serialize_cdr(msg, msg.__msgtype__))


def _imu() -> list[Case]:
    """The camera-IMU solve's bad inputs (docs/imu.md): exit 2, one line naming the file and the fix."""
    g = "imu"
    solve = ["imu", "solve", "{w}/rec", "--serial", SERIAL]
    swap = _imu_csv(lambda lines: [lines[0], lines[2], lines[1], *lines[3:]])
    later = _imu_csv(
        lambda lines: (
            [lines[0]] + [f"{int(x.split(',', 1)[0]) + 10**12},{x.split(',', 1)[1]}" for x in lines[1:]]
        )
    )
    bag = [
        "imu",
        "solve",
        "{w}/bag",
        "--serial",
        SERIAL,
        "--board",
        BOARD,
        "--image-topic",
        "/cam0/image_raw",
        "--imu-topic",
        "/imu0",
    ]
    return [
        Case(g, "imu stamps not increasing", solve, setup=swap, says=("stamps do not increase at line 3",)),
        Case(g, "imu gyro in deg/s", solve, setup=_imu_csv(_scaled(slice(1, 4), 57.29578)), says=("pi/180",)),
        Case(
            g,
            "imu accelerometer in g",
            solve,
            setup=_imu_csv(_scaled(slice(4, 7), 1 / 9.80665)),
            says=("9.80665",),
        ),
        Case(g, "imu and camera logs do not overlap", solve, setup=later, says=("do not overlap in time",)),
        Case(g, "imu camera stamp listed twice", solve, setup=_stamp_listed_twice, says=("is listed twice",)),
        Case(
            g,
            "imu camera without an active calibration",
            ["imu", "solve", "{w}/rec", "--serial", "CAM-NONE"],
            setup=imu_recording,
            says=("has no active calibration",),
        ),
        Case(
            g,
            "imu corners of another board than the registered one",
            [*solve, "--board", BOARD],
            setup=imu_recording,
            says=(f"is no corner of board {BOARD}",),
        ),
        Case(
            g,
            "imu bag without the named topic",
            bag,
            setup=_imu_only_bag,
            says=("has no topic /cam0/image_raw",),
        ),
    ]


def cases() -> list[Case]:
    return [
        *_capture(),
        *_synth(),
        *_solve_check(),
        *_records(),
        *_imports(),
        *_diagnostics(),
        *_admin(),
        *_store(),
        *_seal(),
        *_messages(),
        *_imu(),
    ]
