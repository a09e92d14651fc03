"""An example for every command, printed at the end of its ``--help``.

Kept in one table (not in each command's docstring) so the examples read as a set and a test can
check every one against the real command tree: its command path exists and each option is one the
command accepts.
"""

from __future__ import annotations

from typing import Any

import typer

EXAMPLES: dict[str, tuple[str, ...]] = {
    "": ("calibctl demo", "calibctl --db postgresql://calib@factory-db/calibctl history CAM-0042"),
    "capture": (
        "calibctl capture --serial CAM-0042 --board A17 --source ./shots/",
        "calibctl capture --serial CAM-0042 --board A17 --source /dev/video0 --max-views 30",
        "calibctl capture --serial FE-0007 --board A17 --source ./fisheye/ --image-circle 640,480,470",
        "calibctl capture --serial CAM-0042 --board A17 --source ./shots/ --reference-distance 0.450+-0.0005 "
        "--reference-source ./fixture/",
    ),
    "calibrate": (
        "calibctl calibrate --serial CAM-0042 --board A17 --source /dev/video0",
        "calibctl calibrate --serial CAM-0042 --board A17 --source sweep.mp4 --model auto",
    ),
    "station": (
        "calibctl station --board A17 --source-template /data/shots/{serial}",
        "calibctl station --board A17 --source-template '/data/shots/{serial}/*.png' --serials lot-42.txt "
        "--json",
        "calibctl station status",
    ),
    "station status": (
        "calibctl station status",
        "calibctl station status --spool /var/lib/calibctl/spool.sqlite --json",
    ),
    "station sync": (
        "calibctl station sync",
        "calibctl --db postgresql://calib@factory-db/calibctl station sync --json",
    ),
    "station set-aside": (
        "calibctl station set-aside 3 --reason 'record edited by hand, ticket QA-7'",
        "calibctl station set-aside 3 --reason 'unit scrapped' --operator op-ana --json",
    ),
    "prune": ("calibctl prune", "calibctl prune --now 2026-12-01T00:00:00Z --json"),
    "synth": (
        "calibctl synth ./shots --scenario good --seed 1",
        "calibctl synth ./sweep --scenario video --size 1280x960",
    ),
    "solve": (
        "calibctl solve --serial CAM-0042",
        "calibctl solve 01f22921ea3f --model auto --drop-outliers",
        "calibctl solve --serial CAM-0042 --report reports/",
        "calibctl solve 01f22921ea3f --model fisheye --image-circle 640,480,470",
    ),
    "check": (
        "calibctl check CAM-0042 --source ./eol-shots/",
        "calibctl check CAM-0042@3 --source 'eol/*.png' --reference-distance 0.600+-0.001 --json",
    ),
    "diff": (
        "calibctl diff CAM-0042@3 CAM-0042@4",
        "calibctl diff CAM-0042@3 CAM-0042 --map diff.html --json",
        "calibctl diff CAM-0042@3 CAM-0042-HALFRES@1 --scale 2",
        "calibctl diff --rig stereo-7@1 stereo-7@2",
    ),
    "report": (
        "calibctl report CAM-0042",
        "calibctl report CAM-0042@3 -o CAM-0042-v3.html --force",
        "calibctl report --rig stereo-front@2 -o stereo-front-v2.html",
    ),
    "lint": (
        "calibctl lint camera_front.json camera_front_ros.yaml --format github",
        "calibctl --db sqlite:///station.db lint --all --json",
    ),
    "history": ("calibctl history CAM-0042", "calibctl history CAM-0042 --json"),
    "show": ("calibctl show CAM-0042", "calibctl show CAM-0042@3 --json"),
    "export": (
        "calibctl export CAM-0042 --format ros -o camera_info.yaml",
        "calibctl export CAM-0042@3 -f opencv -o cam.yml --force",
    ),
    "import": ("calibctl import CAM-0042_v3.json", "calibctl import CAM-0042_v3.json --no-activate"),
    "rollback": ("calibctl rollback CAM-0042 --to 2 --reason 'v3 drifted after the lens was knocked'",),
    "triage": (
        "calibctl triage residuals.csv",
        "calibctl triage residuals.csv --focal-px 1000 --plot plots/",
    ),
    "gauge": ("calibctl gauge odometry.csv", "calibctl gauge odometry.csv --window-s 30 --plot plots/"),
    "timeoffset": (
        "calibctl timeoffset gyro.csv camera.csv",
        "calibctl timeoffset gyro.csv camera.csv --window 5",
    ),
    "synth-residuals": ("calibctl synth-residuals res.csv --fault time-offset --seed 2",),
    "demo": ("calibctl demo", "calibctl demo --out /tmp/demo"),
    "board": ("calibctl board list", "calibctl board show A17"),
    "board add": (
        "calibctl board add A17 --kind chessboard --cols 9 --rows 6 --square-mm 25.03 "
        "--uncertainty-mm 0.02 --instrument 'Mitutoyo 500-196' --measured-by anna "
        "--measured-on 2026-03-11 --evidence calipers.jpg",
        "calibctl board add L5 --cols 5 --rows 7 --square-mm 95 --backing-mm 610,850 --pattern-offset-mm 2,0",
    ),
    "board list": ("calibctl board list", "calibctl board list --json"),
    "board show": ("calibctl board show A17", "calibctl board show A17@2 --json"),
    "db": ("calibctl db upgrade", "calibctl --db postgresql://calib@factory-db/calibctl db verify"),
    "db upgrade": ("calibctl db upgrade", "calibctl --db postgresql://calib@factory-db/calibctl db upgrade"),
    "db current": ("calibctl db current", "calibctl --db sqlite:///station.db db current --json"),
    "db verify": ("calibctl db verify", "calibctl db verify --json"),
    "keys": (
        "calibctl keys init --key /etc/calibctl/station.key",
        "calibctl keys export-public --key /etc/calibctl/station.key -o trusted/line3-bench2.pem",
    ),
    "keys init": ("calibctl keys init --key /etc/calibctl/station.key",),
    "keys export-public": (
        "calibctl keys export-public --key /etc/calibctl/station.key -o trusted/line3-bench2.pem",
    ),
    "handeye": (
        "calibctl handeye motions.csv --from base_link --to camera --input poses -o X.json",
        "calibctl handeye arm_poses.csv --from gripper --to camera --images shots/ --serial CAM-0042 "
        "--eye-in-hand --tf-static X_tf.yaml",
    ),
    "synth-motions": (
        "calibctl synth-motions motions.csv --excitation 3d --seed 1",
        "calibctl synth-motions corridor.csv --excitation corridor --time-offset-ms 20",
    ),
    "rig": (
        "calibctl rig add stereo-7 --camera CAM-L --camera CAM-R --design-baseline-mm CAM-L:CAM-R=75.0+-0.5",
        "calibctl rig solve stereo-7",
    ),
    "rig add": (
        "calibctl rig add stereo-7 --camera CAM-L --camera CAM-R --design-baseline-mm CAM-L:CAM-R=75.0+-0.5",
        "calibctl rig add head-3 --camera CAM-A --camera CAM-B --camera CAM-C --root CAM-B",
    ),
    "rig capture": ("calibctl rig capture stereo-7 --board A17 --source CAM-L=left/ --source CAM-R=right/",),
    "rig solve": (
        "calibctl rig solve stereo-7",
        "calibctl rig solve stereo-7 --refine-intrinsics --no-activate",
    ),
    "rig lint": ("calibctl rig lint stereo-7", "calibctl rig lint stereo-7@2 --json"),
    "rig history": ("calibctl rig history stereo-7", "calibctl rig history stereo-7 --json"),
    "rig show": ("calibctl rig show stereo-7", "calibctl rig show stereo-7@2 --json"),
    "rig rollback": (
        "calibctl rig rollback stereo-7 --to 1 --reason 'v2 solved on a bent mount'",
        "calibctl rig rollback stereo-7 --to 1 --expect-active 2 --reason 'v2 solved on a bent mount'",
    ),
    "rig export": (
        "calibctl rig export stereo-7 --format ros -o stereo/",
        "calibctl rig export stereo-7@2 --format opencv -o stereo.yml",
        "calibctl rig export stereo-7 --format bundle -o robot/ --frame "
        "CAM-L=front_left_camera_optical_frame",
    ),
    "rig import": (
        "calibctl rig import stereo-7.json",
        "calibctl rig import robot/ --require-signature --trusted-keys trusted/",
    ),
    "lidar": (
        "calibctl lidar solve --images images/ --scans pcd/ --scan-pattern '*_full.pcd' --camera-info "
        "camera_info.yaml --cols 5 --rows 7 --square-mm 95 --backing-mm 610,850 --box "
        "1,-2.2,-0.8,3.6,1.6,0.6",
    ),
    "lidar solve": (
        "calibctl lidar solve --images images/ --scans pcd/ --scan-pattern '*_full.pcd' --camera-info "
        "camera_info.yaml --cols 5 --rows 7 --square-mm 95 --backing-mm 610,850 --pattern-offset-mm 2,0 "
        "--box 1,-2.2,-0.8,3.6,1.6,0.6",
        "calibctl lidar solve --images shots/ --scans sweeps/ --serial CAM-0042 --board L5 "
        "--box 1,-2,-1,4,2,1 --json",
    ),
    "lidar synth": (
        "calibctl lidar synth lidar-set/ --poses 12 --seed 1",
        "calibctl lidar synth offset-set/ --range-offset-mm 30",
    ),
    "imu": ("calibctl imu solve recording/ --serial CAM-0042 --noise imu.yaml",),
    "imu solve": (
        "calibctl imu solve recording/ --serial CAM-0042 --noise imu.yaml --json",
        "calibctl imu solve recording/ --serial CAM-0042 --rig ROBOT-7 --imu-frame imu --hold-td-ms 0",
    ),
    "imu synth": (
        "calibctl imu synth imu-set/ --seed 1 --td-ms 12",
        "calibctl imu synth corridor-set/ --motion corridor --serial CAM-0042",
    ),
    "rig solve-folders": (
        "calibctl rig solve-folders --source CAM-L=left/ --source CAM-R=right/ --cols 9 --rows 6 "
        "--square-mm 25.0 --export-dir out/",
    ),
    "fleet": (
        "calibctl fleet add amr-017 --serial CAM-0042 --serial CAM-0043",
        "calibctl fleet status --json",
    ),
    "fleet add": ("calibctl fleet add amr-017 --serial CAM-0042 --rig stereo-7 --reason 'commissioned'",),
    "fleet assign": (
        "calibctl fleet assign amr-017 CAM-0042@4 --reason 'recalibrated after the lens was knocked'",
    ),
    "fleet status": ("calibctl fleet status", "calibctl fleet status --json"),
    "fleet ingest": (
        "calibctl fleet ingest amr-017-2026-11-27.jsonl",
        "calibctl fleet ingest reports/*.jsonl --json",
    ),
    "fleet trends": ("calibctl fleet trends CAM-0042", "calibctl fleet trends CAM-0042 --json"),
    "fleet rollout": (
        "calibctl fleet rollout start recal-2026-12 --target CAM-0042@4 --target CAM-0043@3 --canary amr-017 "
        "--reason 'new lens model'",
        "calibctl fleet rollout promote recal-2026-12 --reason 'canary healthy'",
    ),
    "fleet rollout start": (
        "calibctl fleet rollout start recal-2026-12 --target CAM-0042@4 --canary amr-017 "
        "--reason 'new lens model'",
    ),
    "fleet rollout promote": (
        "calibctl fleet rollout promote recal-2026-12 --reason 'canary healthy for a week'",
    ),
    "fleet rollout rollback": (
        "calibctl fleet rollout rollback recal-2026-12 --reason 'canary checks fail'",
    ),
}


def epilog(path: str) -> str:
    r"""The ``Examples:`` block for command ``path`` ("" is calibctl itself); ``\b`` keeps click
    from re-wrapping the lines."""
    examples = EXAMPLES.get(path)
    if not examples:  # tests/cli/app/test_cli_habits.py fails on this; a user's --help never does
        return ""
    lines = "\n".join(f"  $ {example}" for example in examples)
    return f"\b\nExamples:\n{lines}"


def _name(info: Any) -> str:
    return str(info.name or info.callback.__name__).lower().replace("_", "-")


def attach_examples(app: typer.Typer, prefix: str = "") -> None:
    """Put each command's examples into its epilog (groups and sub-commands too)."""
    for command in app.registered_commands:
        command.epilog = epilog(f"{prefix}{_name(command)}")
    for group in app.registered_groups:
        sub = group.typer_instance
        if sub is None:  # pragma: no cover - every calibctl group is a Typer
            continue
        name = group.name or sub.info.name
        group.epilog = epilog(f"{prefix}{name}")
        attach_examples(sub, f"{prefix}{name} ")
