"""The one loader for JSON and YAML that comes from outside: bounded in size, depth, numbers and text.

Every file calibctl parses may be hostile (an artifact to import or lint, a station file, a rig
definition). Unbounded, a 602-byte YAML "billion laughs" file took 73 s and 6 GB, 100 000-deep nesting
and 5000-digit integers ended in tracebacks, and a NUL in a string reached PostgreSQL (which refuses
it). Here each of those is an ``InputError`` (exit 2) naming the file, found before anything is built
from it:

* size: at most ``CALIBCTL_MAX_INPUT_MB`` (default 64 MiB, ~100x the largest real artifact) is read;
* YAML: aliases are refused (no real calibration file uses anchors; expansion bombs are made of them);
* nesting: at most ``MAX_DEPTH`` levels (real documents use fewer than 10);
* numbers: integers of at most ``MAX_INT_DIGITS`` digits, numeric literals of at most ``MAX_NUMBER_CHARS``;
* text: NUL and other control characters (tab, newline and carriage return excepted) are refused in
  every string and key.
"""

from __future__ import annotations

import functools
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from calibctl import files
from calibctl.errors import InputError, UsageError

MAX_INPUT_ENV = "CALIBCTL_MAX_INPUT_MB"
DEFAULT_MAX_INPUT_MB = 64.0
MAX_DEPTH = 64
MAX_INT_DIGITS = 30
MAX_NUMBER_CHARS = 64
_ALLOWED_CONTROLS = {"\t", "\n", "\r"}
_CONTROLS = {chr(c) for c in (*range(0x20), 0x7F)} - _ALLOWED_CONTROLS


def max_input_bytes(env: Mapping[str, str] | None = None) -> int:
    """The largest input file read (``CALIBCTL_MAX_INPUT_MB``, MiB; default 64)."""
    env = os.environ if env is None else env
    raw = env.get(MAX_INPUT_ENV, "").strip()
    if not raw:
        return int(DEFAULT_MAX_INPUT_MB * 2**20)
    try:
        value = float(raw)
    except ValueError:
        value = -1.0
    if not 0 < value <= 65536:
        raise UsageError(f"{MAX_INPUT_ENV}={raw!r} is not a size in MiB in (0, 65536]")
    return int(value * 2**20)


def check_size(path: Path, what: str = "read") -> int:
    """The size of ``path``; InputError when it is over the limit (nothing of it is read)."""
    limit = max_input_bytes()
    with files.file_errors(what, path):
        size = Path(path).stat().st_size
    if size > limit:
        raise InputError(
            f"{path} is {size / 2**20:.1f} MiB, over the {limit / 2**20:g} MiB input limit",
            f"no calibration file is that large; if this one really is, raise {MAX_INPUT_ENV}",
        )
    return size


def _check_int(text: str, source: str) -> str:
    digits = text.lstrip("+-").replace("_", "")
    if len(digits) > MAX_INT_DIGITS:
        raise InputError(
            f"{source}: an integer of {len(digits)} digits (at most {MAX_INT_DIGITS} are accepted)",
            "no calibration number needs that many digits; is this the right file?",
        )
    return text


def _check_float(text: str, source: str) -> str:
    if len(text) > MAX_NUMBER_CHARS:
        raise InputError(
            f"{source}: a number written with {len(text)} characters (at most {MAX_NUMBER_CHARS})",
            "is this the right file?",
        )
    return text


def check_tree(data: Any, source: str) -> Any:
    """``data`` unchanged, after checking depth and text of every node (iterative: no recursion limit)."""
    stack: list[tuple[Any, int, str]] = [(data, 1, "")]
    while stack:
        node, depth, where = stack.pop()
        if depth > MAX_DEPTH:
            raise InputError(
                f"{source}: nested more than {MAX_DEPTH} levels deep (at {where or 'the top'})",
                "real calibration files nest a few levels; is this the right file?",
            )
        if isinstance(node, str):
            check_text(node, source, where)
        elif isinstance(node, dict):
            for key, value in node.items():
                check_text(str(key), source, where)
                stack.append((value, depth + 1, f"{where}.{key}" if where else str(key)))
        elif isinstance(node, list | tuple):
            stack.extend((value, depth + 1, f"{where}[{i}]") for i, value in enumerate(node))
    return data


def printable(text: str) -> str:
    """``text`` safe to print and to store as UTF-8: each control character (newline and tab kept) as
    ``\\xNN``, and each byte of a file name that is not UTF-8 (Python's surrogate escapes) as ``\\xNN``,
    so a name holding ESC sequences cannot drive the terminal and one in Latin-1 cannot end in a
    UnicodeEncodeError when stored."""
    if text.isprintable():
        return text
    out = []
    for ch in text:
        code = ord(ch)
        if ch in "\n\t":
            out.append(ch)
        elif 0xDC80 <= code <= 0xDCFF:  # os.fsdecode's escape of the raw byte code - 0xDC00
            out.append(f"\\x{code - 0xDC00:02x}")
        elif 0xD800 <= code <= 0xDFFF:
            out.append(f"\\u{code:04x}")
        elif code < 0x20 or code == 0x7F or 0x80 <= code < 0xA0:
            out.append(f"\\x{code:02x}")
        else:
            out.append(ch)
    return "".join(out)


def check_text(text: str, source: str, where: str) -> None:
    """InputError when ``text`` holds NUL or another control character (tab, newline, CR excepted)."""
    bad = next((c for c in text if c in _CONTROLS), None)
    if bad is not None:
        name = (
            "a NUL character"
            if bad == "\x00"
            else f"control character {bad.encode('unicode_escape').decode()}"
        )
        raise InputError(
            f"{source}: {where or 'a key'} holds {name}", "text fields may not hold control characters"
        )


def parse_json(text: str, source: str) -> Any:
    """JSON with bounded numbers, depth and text."""
    try:
        data = json.loads(
            text,
            parse_int=lambda s: int(_check_int(s, source)),
            parse_float=lambda s: float(_check_float(s, source)),
        )
    except json.JSONDecodeError as exc:
        raise InputError(
            f"{source}: malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
        ) from exc
    except RecursionError:
        raise InputError(
            f"{source}: nested more than {MAX_DEPTH} levels deep", "is this the right file?"
        ) from None
    return check_tree(data, source)


@functools.cache
def _loader_class() -> Any:
    """SafeLoader without aliases and with bounded numbers; made on first use, as yaml is imported only
    when a YAML file is read (a read of JSON or of the store never pays its import)."""
    import yaml

    class BoundedLoader(yaml.SafeLoader):
        source = "YAML"  # names the file in messages

        def compose_node(self, parent: Any, index: Any) -> Any:
            if self.check_event(yaml.AliasEvent):
                event = self.peek_event()
                raise InputError(
                    f"{self.source}: YAML alias *{event.anchor} at line {event.start_mark.line + 1}: "
                    "aliases are not accepted",
                    "write the values out; calibration files use no anchors",
                )
            if getattr(self, "_depth", 0) >= MAX_DEPTH:
                raise InputError(
                    f"{self.source}: nested more than {MAX_DEPTH} levels deep", "is this the right file?"
                )
            self._depth = getattr(self, "_depth", 0) + 1
            try:
                return super().compose_node(parent, index)
            finally:
                self._depth -= 1

        def construct_yaml_int(self, node: Any) -> int:
            _check_int(str(node.value), self.source)
            return super().construct_yaml_int(node)

        def construct_yaml_float(self, node: Any) -> float:
            _check_float(str(node.value), self.source)
            return super().construct_yaml_float(node)

    BoundedLoader.add_constructor("tag:yaml.org,2002:int", BoundedLoader.construct_yaml_int)
    BoundedLoader.add_constructor("tag:yaml.org,2002:float", BoundedLoader.construct_yaml_float)
    return BoundedLoader


def parse_yaml(text: str, source: str) -> Any:
    """YAML (safe subset, no aliases) with bounded numbers, depth and text."""
    import yaml

    loader = _loader_class()(text)
    loader.source = source
    try:
        data = loader.get_single_data()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1} column {mark.column + 1}" if mark else ""
        raise InputError(f"{source}: malformed YAML{where}: {getattr(exc, 'problem', None) or exc}") from exc
    finally:
        loader.dispose()
    return check_tree(data, source)


def read_text(path: Path, what: str = "read") -> str:
    """A UTF-8 text file of at most the input limit (an over-size file is refused before it is read)."""
    check_size(path, what)
    return files.read_text(path, what, max_bytes=max_input_bytes())


def load_file(path: Path, what: str = "read") -> Any:
    """A JSON (``.json``) or YAML file, bounded in every way above."""
    text = read_text(path, what)
    return (
        parse_json(text, str(path)) if Path(path).suffix.lower() == ".json" else parse_yaml(text, str(path))
    )
