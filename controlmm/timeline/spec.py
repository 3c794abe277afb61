"""The timeline specification: tracks of (body part, prompt, start and end in seconds).

JSON form (``controlmm timeline spec.json``)::

    {
      "seconds": 6.0,                        # optional: length (default: the latest track end), 2..9.8 s
      "base": "a person stands still",       # optional: prompt of the first whole-body pass
      "tracks": [
        {"part": "legs", "prompt": "a person walks forward", "start": 0, "end": 6},
        {"part": "right arm", "prompt": "a person waves the right hand", "start": 2, "end": 4,
         "probe": {"family": "wave_right", "claims": {"hand": "right"}}}
      ]
    }

Python form::

    Timeline(tracks=(Track("legs", "a person walks forward", 0, 6),
                     Track("right_arm", "a person waves the right hand", 2, 4)), seconds=6)

Parts are listed in :mod:`controlmm.timeline.parts` (``legs``, ``torso``, ``head``, ``left_arm``,
``right_arm``, ``whole_body``; spaces or hyphens may replace underscores). Tracks may overlap: they are
applied in the order given, and where two tracks claim the same joint at the same frame the later one
wins. A track's optional ``probe`` names a text-adherence probe (:mod:`controlmm.corpus.probes`) that its
span of the result is checked with.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

from controlmm.corpus.probes import PROBES
from controlmm.errors import ControlMMError, InputFileError
from controlmm.motion.skeleton import FPS, MAX_FRAMES, MIN_FRAMES
from controlmm.timeline.parts import part_joints, part_name

MIN_SECONDS = MIN_FRAMES / FPS  # 2.0
MAX_SECONDS = MAX_FRAMES / FPS  # 9.8
MIN_SPAN_FRAMES = 4  # one token of the tokenizer (4 frames at 20 fps)

TIMELINE_KEYS = ("seconds", "base", "tracks")
TRACK_KEYS = ("part", "prompt", "start", "end", "probe")


@dataclass(frozen=True)
class Track:
    """One body part doing what ``prompt`` says from ``start`` to ``end`` seconds."""

    part: str
    prompt: str
    start: float
    end: float
    probe: dict[str, Any] | None = field(default=None, compare=False)  # {"family": ..., "claims": {...}}

    def __post_init__(self) -> None:
        object.__setattr__(self, "part", part_name(self.part))
        if not isinstance(self.prompt, str) or not self.prompt.strip():
            raise ControlMMError(f"track '{self.part}' needs a non-empty prompt; got {self.prompt!r}")
        for name in ("start", "end"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ControlMMError(
                    f"track '{self.part}': {name} must be a number of seconds; got {value!r}"
                )
            object.__setattr__(self, name, float(value))
        if self.start < 0:
            raise ControlMMError(f"track '{self.part}': start {self.start:g} s is negative; allowed >= 0")
        if self.end - self.start < MIN_SPAN_FRAMES / FPS - 1e-9:
            raise ControlMMError(
                f"track '{self.part}': span {self.start:g}..{self.end:g} s is too short; "
                f"end must be at least {MIN_SPAN_FRAMES / FPS:g} s after start"
            )
        if self.probe is not None:
            _check_probe(self.probe, self.part)

    @property
    def joints(self) -> tuple[int, ...]:
        return part_joints(self.part)

    def frames(self, num_frames: int) -> tuple[int, int]:
        """Frame span [first, last + 1) at 20 fps, clipped to the motion."""
        first = min(int(round(self.start * FPS)), num_frames)
        return first, min(int(round(self.end * FPS)), num_frames)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"part": self.part, "prompt": self.prompt, "start": self.start, "end": self.end}
        if self.probe is not None:
            out["probe"] = self.probe
        return out


@dataclass(frozen=True)
class Timeline:
    """Tracks, the total length and the prompt of the first (whole-body) pass.

    ``seconds`` defaults to the latest track end; ``base`` to the first track's prompt.
    """

    tracks: tuple[Track, ...]
    seconds: float | None = None
    base: str | None = None

    def __post_init__(self) -> None:
        tracks = tuple(self.tracks)
        if not tracks:
            raise ControlMMError("a timeline needs at least one track")
        for t in tracks:
            if not isinstance(t, Track):
                raise ControlMMError(f"timeline tracks must be Track objects; got {type(t).__name__}")
        object.__setattr__(self, "tracks", tracks)
        latest = max(t.end for t in tracks)
        seconds = latest if self.seconds is None else self.seconds
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not math.isfinite(seconds):
            raise ControlMMError(f"timeline seconds must be a number; got {seconds!r}")
        if not MIN_SECONDS <= seconds <= MAX_SECONDS + 1e-9:
            raise ControlMMError(
                f"timeline length {seconds:g} s is out of range; allowed "
                f"{MIN_SECONDS:g}..{MAX_SECONDS:g} s (tracks end by then)"
            )
        length = float(seconds)
        object.__setattr__(self, "seconds", length)
        for k, t in enumerate(tracks):
            if t.end > length + 1e-9:
                raise ControlMMError(
                    f"track {k} ('{t.part}') ends at {t.end:g} s, after the timeline's end ({length:g} s)"
                )
        if self.base is not None and (not isinstance(self.base, str) or not self.base.strip()):
            raise ControlMMError(f"base must be a non-empty prompt; got {self.base!r}")

    @property
    def num_frames(self) -> int:
        return int(round(cast(float, self.seconds) * FPS))  # __post_init__ sets seconds

    @property
    def base_prompt(self) -> str:
        return self.base if self.base is not None else self.tracks[0].prompt

    # -- JSON ---------------------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Any) -> Timeline:
        """Parse and validate the JSON structure (see the module docstring)."""
        if not isinstance(data, dict):
            raise ControlMMError(f"a timeline spec must be a JSON object; got {type(data).__name__}")
        unknown = sorted(set(data) - set(TIMELINE_KEYS))
        if unknown:
            raise ControlMMError(
                f"unknown timeline key(s) {', '.join(unknown)}; allowed: {', '.join(TIMELINE_KEYS)}"
            )
        items = data.get("tracks")
        if not isinstance(items, list) or not items:
            raise ControlMMError("a timeline spec needs a non-empty 'tracks' list")
        tracks = []
        for k, item in enumerate(items):
            if not isinstance(item, dict):
                raise ControlMMError(f"track {k} must be a JSON object; got {type(item).__name__}")
            unknown = sorted(set(item) - set(TRACK_KEYS))
            if unknown:
                raise ControlMMError(
                    f"track {k}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(TRACK_KEYS)}"
                )
            missing = [key for key in ("part", "prompt", "start", "end") if key not in item]
            if missing:
                raise ControlMMError(f"track {k} is missing {', '.join(missing)}")
            try:
                tracks.append(
                    Track(item["part"], item["prompt"], item["start"], item["end"], item.get("probe"))
                )
            except ControlMMError as exc:
                raise ControlMMError(f"track {k}: {exc}") from None
        return cls(tuple(tracks), seconds=data.get("seconds"), base=data.get("base"))

    @classmethod
    def load(cls, path: str | Path) -> Timeline:
        """Read a JSON timeline spec file."""
        path = Path(path)
        if not path.is_file():
            raise InputFileError(f"timeline spec '{path}' does not exist")
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputFileError(f"timeline spec '{path}' is not valid JSON ({exc})") from None
        return cls.from_dict(data)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"seconds": self.seconds}
        if self.base is not None:
            out["base"] = self.base
        out["tracks"] = [t.to_dict() for t in self.tracks]
        return out


def _check_probe(probe: Any, part: str) -> None:
    if not isinstance(probe, dict) or "family" not in probe or set(probe) - {"family", "claims"}:
        raise ControlMMError(
            f'track \'{part}\': probe must be {{"family": NAME, "claims": {{...}}}}; got {probe!r}'
        )
    if probe["family"] not in PROBES:
        raise ControlMMError(
            f"track '{part}': no probe for family '{probe['family']}'; known: {', '.join(PROBES)}"
        )
    if not isinstance(probe.get("claims", {}), dict):
        raise ControlMMError(f"track '{part}': probe claims must be a JSON object; got {probe['claims']!r}")
