"""How the rig commands print: the solve-folders run, the solved tree, the verdict and findings."""

from __future__ import annotations

from typing import Any

from calibctl.cli.render import say

MAX_UNMATCHED_ROWS = 10  # unmatched photos listed; --json has them all


def render_run(doc: dict[str, Any]) -> None:
    """Human report of ``rig_folders.run_json``."""
    unmatched = doc["unmatched"]
    say(
        f"rig {' '.join(doc['cameras'])}: {doc['frames']} synchronised frames, {len(unmatched)} unmatched "
        "photo(s)"
    )
    if "timing" in doc:
        render_timing(doc["timing"])
    render_unmatched([(u["camera"], u["file"], u["reason"]) for u in unmatched])
    for f in doc.get("refused", []):
        say(f"  refused {f['message']} -> {f['fix']}")
    for name, counts in doc["images"].items():
        say(f"  {name}: " + ", ".join(f"{n} {s}" for s, n in sorted(counts.items())))
    say("  shared views: " + ", ".join(f"{p} {n}" for p, n in doc["shared_views"].items()))
    g = doc["gate"]
    say(
        f"  gate rig-connected {'pass' if g['passed'] else 'FAIL'}  {g['message']}"
        + (f" -> {g['hint']}" if g["hint"] else "")
    )
    if "tree" in doc:
        render_solution(doc)
    render_verdict(doc)


def render_timing(timing: dict[str, Any]) -> None:
    """How the frames were paired by time (``rig_video.timing_json``)."""
    spread = timing["spread_ms"]
    line = (
        f"  paired by time ({timing['times']}): {timing['rig_frames']} rig frames within "
        f"{timing['tolerance_ms']:g} ms, {timing['outside_tolerance']} frame(s) outside"
    )
    if spread["median"] is not None:
        line += f"; spread median {spread['median']:.2f} ms, max {spread['max']:.2f} ms"
    say(line)
    by_offset: dict[int, list[str]] = {}
    for name, offset in timing["index_offset"].items():
        by_offset.setdefault(offset, []).append(name)
    for offset, names in by_offset.items():
        say(f"  the timestamps number the frames of {', '.join(names)} from {offset}: read as video frame 0")
    for name, shift in timing.get("frame_shift", {}).items():
        say(
            f"  camera {name}'s frame i read at the time listed for its frame i{-shift:+d} "
            f"(--frame-shift {name}={shift:+d})"
        )
    dropped, sd = timing.get("exposure_dropped", {}), timing.get("exposure_offset_sd_ms", {})
    for name, ms in timing.get("exposure_offset_ms", {}).items():
        lost = ", ".join(f"{n} {why}" for why, n in dropped.get(name, {}).items()) or "none"
        how = (
            f"estimated from the data, frame-bootstrap sd {sd[name]:.1f} ms"
            if name in sd
            else f"--exposure-offset {name}={ms:+g}"
        )
        say(
            f"  camera {name}'s corners moved to its frames' listed times, exposed {ms:+.1f} ms after them "
            f"({how}); rig frames dropped: {lost}"
        )


def render_unmatched(rows: list[tuple[str, str, str]]) -> None:
    """(camera, file, reason) of the photos no frame took, the first MAX_UNMATCHED_ROWS, then how many
    more."""
    for camera, file, reason in rows[:MAX_UNMATCHED_ROWS]:
        say(f"  unmatched {camera} {file}: {reason}")
    if len(rows) > MAX_UNMATCHED_ROWS:
        say(f"  ... {len(rows) - MAX_UNMATCHED_ROWS} more unmatched (see --json)")


def render_solution(doc: dict[str, Any]) -> None:
    """The tree, fit and held-out numbers of a solved ``rig_folders.run_json``."""
    say(f"tree from {doc['root']} ({doc['solver']}):")
    for e in doc["tree"]:
        say(
            f"  T_{e['parent']}_{e['child']}: |t| = {e['translation_mm']:.3f} +/- "
            f"{e['sigma_translation_mm']:.3f} mm, "
            f"rotation {e['rotation_deg']:.4f} +/- {e['sigma_rotation_deg']:.4f} deg"
        )
    held = doc.get("held_out", {})
    for name, rms in doc["fit_rms_px"].items():
        say(
            f"  {name}: RMS fit {rms:.3f} px / held-out "
            f"{held.get('rms_px', {}).get(name, float('nan')):.3f} px "
            f"({held.get('folds', 0)}-fold)"
        )
    for p in doc["pairs"]:
        line = (
            f"  pair {p['pair']}: baseline {p['baseline_mm']:.3f} +/- {p['sigma_baseline_mm']:.3f} mm, "
            f"{p['shared_views']} shared views"
        )
        if "epipolar_rms_px" in p:
            line += (
                f"; held-out epipolar RMS {p['epipolar_rms_px']:.3f} px (max {p['epipolar_max_px']:.3f}), "
                f"rectified rows RMS {p['rectified_rms_px']:.3f} px"
            )
        say(line)
    for lc in doc["loops"]:
        say(
            f"  loop {'-'.join(lc['cycle'])}: {lc['rotation_deg']:.4f} deg (sigma "
            f"{lc['sigma_rotation_deg']:.4f}), "
            f"{lc['translation_mm']:.3f} mm (sigma {lc['sigma_translation_mm']:.3f}), Mahalanobis "
            f"{lc['mahalanobis']:.2f}"
        )


def render_verdict(doc: dict[str, Any]) -> None:
    """The verdict lines of ``rig_folders.run_json`` (after the gate, when the rig was solved or judged)."""
    if "verdict" not in doc:
        return
    say(f"verdict: {doc['verdict']}")
    for f in doc["lint"]:
        say(f"  {f['severity']} {f['rule']}: {f['message']}" + (f" -> {f['fix']}" if f.get("fix") else ""))


def print_findings(findings: list[Any]) -> None:
    if not findings:
        say("  lint: clean")
    for f in findings:
        say(f"  {f.severity} {f.rule}: {f.message}" + (f" -> {f.fix}" if f.fix else ""))
