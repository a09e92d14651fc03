"""What --source names and which files a folder, glob or list file selects (no store, no detection)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from calibctl.core.capture.image_outcomes import PROCESS_MIN_FILES
from calibctl.errors import EXIT_CANNOT_RUN, InputError
from calibctl.workflows.camera import capture_sources as sources


@pytest.fixture
def shots(tmp_path: Path) -> Path:
    folder = tmp_path / "shots"
    (folder / "sub").mkdir(parents=True)
    for name in ("left01.jpg", "left02.png", "right01.jpg", "notes.md", "sub/left03.jpg"):
        (folder / name).write_bytes(b"x")
    return folder


def test_a_quoted_glob_selects_its_matches_named_relative_to_its_fixed_folders(shots: Path) -> None:
    spec = sources.resolve_source(str(shots / "left*"))
    assert spec.kind == sources.GLOB and spec.recorded == str(shots / "left*")
    images = sources.select_images(spec)
    assert images.names == ["left01.jpg", "left02.png"] and images.base == shots
    everything = sources.select_images(sources.resolve_source(str(shots / "**" / "*")))
    assert everything.names == ["left01.jpg", "left02.png", "right01.jpg", "sub/left03.jpg"]
    assert everything.ignored == ["notes.md"]


def test_a_relative_glob_is_relative_to_the_working_directory(shots: Path, monkeypatch) -> None:
    monkeypatch.chdir(shots.parent)
    images = sources.select_images(sources.resolve_source("shots/*01.jpg"))
    assert images.names == ["left01.jpg", "right01.jpg"]
    assert [p.resolve() for p in images.paths] == [shots / "left01.jpg", shots / "right01.jpg"]


def test_a_glob_matching_no_image_names_what_it_matched(shots: Path) -> None:
    with pytest.raises(InputError) as nothing:
        sources.select_images(sources.resolve_source(str(shots / "top*.jpg")))
    assert (
        f"--source '{shots / 'top*.jpg'}' matches no image file; nothing was stored" in nothing.value.message
    )
    assert nothing.value.exit_code == EXIT_CANNOT_RUN
    with pytest.raises(InputError, match=r"1 file\(s\), none an image by its suffix: notes.md"):
        sources.select_images(sources.resolve_source(str(shots / "*.md")))


def test_a_list_file_is_read_relative_to_its_own_folder(shots: Path, tmp_path: Path, monkeypatch) -> None:
    lists = tmp_path / "lists"
    lists.mkdir()
    listing = lists / "left.txt"
    listing.write_text(
        f"# left camera\n../shots/left01.jpg\n\n  ../shots/sub/left03.jpg  \n{shots / 'left02.png'}\n"
        "../shots/left01.jpg\n"
    )
    monkeypatch.chdir(shots / "sub")  # the working directory plays no part
    spec = sources.resolve_source(str(listing))
    assert spec.kind == sources.LIST and spec.recorded == str(listing)
    images = sources.select_images(spec)
    # relative entries relative to the list's folder; an absolute one as written, never ../../..
    assert images.names == ["../shots/left01.jpg", "../shots/sub/left03.jpg", str(shots / "left02.png")]
    assert images.paths[0].resolve() == shots / "left01.jpg"


def test_a_list_file_naming_missing_or_odd_files_is_refused_naming_each(shots: Path) -> None:
    listing = shots / "session.lst"
    listing.write_text("left01.jpg\nleft09.jpg\nsub\nnotes.md\n")
    with pytest.raises(InputError) as bad:
        sources.select_images(sources.resolve_source(str(listing)))
    assert "names 3 file(s) that cannot be used; nothing was stored" in bad.value.message
    assert (
        "line 2: left09.jpg (missing), line 3: sub (a folder), line 4: notes.md (not an image by its suffix)"
        in bad.value.message
    )
    assert str(shots) in bad.value.hint
    (shots / "empty.txt").write_text("# nothing yet\n")
    with pytest.raises(InputError, match="names no image"):
        sources.select_images(sources.resolve_source(str(shots / "empty.txt")))
    (shots / "binary.list").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(InputError, match="cannot read the list file"):
        sources.select_images(sources.resolve_source(str(shots / "binary.list")))


def test_mixed_sizes_are_an_error_for_a_glob_or_list_only(shots: Path) -> None:
    sizes = {"a.jpg": (1280, 720), "b.jpg": (1280, 720), "c.jpg": (1281, 721)}
    glob_spec = sources.resolve_source(str(shots / "*.jpg"))
    error = sources.mixed_sizes_error(glob_spec, sizes)
    assert (
        error is not None and "mixes image sizes (1280x720: a.jpg, b.jpg; 1281x721: c.jpg)" in error.message
    )
    assert sources.mixed_sizes_error(glob_spec, {"a.jpg": (640, 480)}) is None
    assert (
        sources.mixed_sizes_error(sources.resolve_source(str(shots)), sizes) is None
    )  # a folder: wrong_size


def test_long_listings_are_cut(shots: Path) -> None:
    listing = shots / "many.txt"
    listing.write_text("".join(f"gone{i:02d}.jpg\n" for i in range(25)))
    with pytest.raises(InputError) as bad:
        sources.select_images(sources.resolve_source(str(listing)))
    assert "line 10: gone09.jpg (missing) and 15 more" in bad.value.message
    assert os.sep + "many.txt" in bad.value.message


@pytest.fixture
def server_starts(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Calls of worker_pool.start_server by start_detection_early (the server itself is not started)."""
    calls: list[int] = []
    monkeypatch.setattr(sources.worker_pool, "start_server", lambda: calls.append(1))
    monkeypatch.setattr(sources.worker_pool, "is_warm", lambda workers: False)
    return calls


def _pngs(folder: Path, n: int) -> Path:
    folder.mkdir()
    for i in range(n):
        (folder / f"img-{i:03d}.png").write_bytes(b"")  # only counted, never decoded
    return folder


@pytest.mark.parametrize(
    ("images", "jobs", "started"),
    [(PROCESS_MIN_FILES, 2, True), (PROCESS_MIN_FILES - 1, 2, False), (PROCESS_MIN_FILES, 1, False)],
)
def test_the_fork_server_starts_early_only_for_a_capture_the_pool_will_detect(
    tmp_path: Path, server_starts: list[int], images: int, jobs: int, started: bool
) -> None:
    folder = _pngs(tmp_path / "shots", images)
    sources.start_detection_early(str(folder), jobs)
    sources.start_detection_early(str(folder / "*.png"), jobs)  # the same files as a glob
    assert len(server_starts) == (2 if started else 0)


@pytest.mark.parametrize("source", ["missing-folder", "/dev/video7", "empty", "clip.mp4"])
def test_a_source_the_pool_will_not_detect_starts_nothing_and_raises_nothing(
    tmp_path: Path, server_starts: list[int], monkeypatch: pytest.MonkeyPatch, source: str
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "empty").mkdir()
    (tmp_path / "clip.mp4").write_bytes(b"\0" * 64)
    sources.start_detection_early(source, 4)  # the capture itself reports a bad source, with its exit code
    assert server_starts == []


def test_start_server_returns_and_the_pool_forks_from_that_server() -> None:
    from multiprocessing import forkserver

    from calibctl.core.capture import worker_pool

    worker_pool.start_server()
    pid = forkserver._forkserver._forkserver_pid  # noqa: SLF001 - which server the pool uses
    assert pid is not None
    worker_pool.warm(2)
    assert forkserver._forkserver._forkserver_pid == pid  # noqa: SLF001 - the same server: not started twice
