"""Reading the official ``opt.txt`` files (the option dump written next to every official checkpoint).

Format: a header line ``------------ Options -------------``, one ``key: value`` line per option
(sorted), a footer line ``-------------- End ----------------``. Values are Python-ish literals:
``True``/``False``, ``None``, integers, floats, lists (``[50000]``) and bare strings. The official
reader splits on the first ``": "``; so does this one.
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

from controlmm.errors import InputFileError


def parse_value(text: str) -> Any:
    """``"True"`` -> True, ``"None"`` -> None, ``"512"`` -> 512, ``"0.2"`` -> 0.2, ``"[1, 2]"`` -> [1, 2];
    anything else stays a string."""
    text = text.strip()
    if text in ("True", "False"):
        return text == "True"
    if text == "None":
        return None
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError, MemoryError, RecursionError):
        return text
    return value if isinstance(value, (int, float, list, tuple)) and not isinstance(value, bool) else text


def read_opt(path: str | Path) -> dict[str, Any]:
    """The options of an ``opt.txt`` as a dict; one-line error for an unreadable or malformed file."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise InputFileError(f"cannot read '{path}': {exc.strerror or exc}") from None
    options: dict[str, Any] = {}
    for number, line in enumerate(lines, start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("---"):
            continue
        key, sep, value = line.partition(": ")
        if not sep:
            key, sep, value = line.partition(":")
        if not sep or not key.strip():
            raise InputFileError(f"'{path}' line {number} is not 'key: value': {stripped[:60]!r}")
        options[key.strip()] = parse_value(value)
    return options
