"""Probes on a model: generate from each held-out caption and check the claims of its words.

```python
from controlmm.eval.cases import evaluate, list_cases
from controlmm.eval.model_probes import generated_motions, select_cases
from controlmm.generate import load_model

cases = select_cases(list_cases("corpus", "test"), samples=10, seed=0)    # <= 10 captions per family
source = generated_motions(load_model("MODEL_DIR"), cases, seed=0)       # case -> Motion
report = evaluate(cases, source)
```

Each case is generated from ``case.caption`` with ``case.frames`` frames (the length of the clip the
caption describes); cases are generated in batches, batch k with seed ``seed + k``, so a run is
reproducible for a given (cases, seed, batch size).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from controlmm.corpus.probes import PROBES, ProbeCase
from controlmm.errors import ControlMMError
from controlmm.eval.cases import clip_features
from controlmm.generate import MotionModel, generate
from controlmm.models.rvqvae import RVQVAE
from controlmm.motion import Motion
from controlmm.motion.skeleton import MAX_FRAMES, MIN_FRAMES


def select_cases(
    cases: Sequence[ProbeCase],
    families: Sequence[str] | None = None,
    samples: int | None = None,
    seed: int = 0,
) -> list[ProbeCase]:
    """Cases of the given families (all by default), at most ``samples`` per family (a seeded random
    choice, kept in the original order)."""
    cases = list(cases)
    if families:
        unknown = [f for f in families if f not in PROBES]
        if unknown:
            raise ControlMMError(f"unknown family {', '.join(unknown)}; known: {', '.join(PROBES)}")
        present = sorted({c.family for c in cases})
        absent = [f for f in families if f not in present]
        if absent:
            raise ControlMMError(
                f"no captions of {', '.join(absent)} in this split; present: {', '.join(present)}"
            )
        cases = [c for c in cases if c.family in set(families)]
    if samples is not None:
        if samples < 1:
            raise ControlMMError(f"samples per family must be at least 1; got {samples}")
        rng = np.random.default_rng(seed)
        keep: set[int] = set()
        for family in dict.fromkeys(c.family for c in cases):
            idx = [i for i, c in enumerate(cases) if c.family == family]
            keep.update(
                int(i) for i in (rng.choice(idx, samples, replace=False) if len(idx) > samples else idx)
            )
        cases = [c for i, c in enumerate(cases) if i in keep]
    return cases


def generated_motions(
    model: MotionModel,
    cases: Sequence[ProbeCase],
    seed: int = 0,
    batch_size: int = 32,
    progress: bool = False,
    **generate_kwargs: Any,
) -> Callable[[ProbeCase], Motion]:
    """Generate one motion per case (text ``case.caption``, ``case.frames`` frames) with a loaded
    :class:`~controlmm.models.MotionModel`; returns the ``motion_for`` function of
    :func:`controlmm.eval.cases.evaluate`."""
    if batch_size < 1:
        raise ControlMMError(f"batch size must be at least 1; got {batch_size}")
    motions: dict[tuple[str, str], Motion] = {}
    starts = range(0, len(cases), batch_size)
    for k, start in enumerate(tqdm(starts, desc="generating", unit="batch", disable=not progress)):
        chunk = cases[start : start + batch_size]
        frames = [min(max(c.frames, MIN_FRAMES), MAX_FRAMES) for c in chunk]
        result = generate(
            model,
            [c.caption for c in chunk],
            frames=frames,
            seed=seed + k,
            batch_size=batch_size,
            **generate_kwargs,
        )
        for case, motion in zip(chunk, result.motions, strict=True):
            motions[(case.clip_id, case.caption)] = motion

    def motion_for(case: ProbeCase) -> Motion:
        return motions[(case.clip_id, case.caption)]

    return motion_for


def tokenized_motions(
    model: MotionModel, data_dir: str, layers: int | None = None
) -> Callable[[ProbeCase], Motion]:
    """The ground truth of each case passed through the model's tokenizer (encode, keep the first
    ``layers`` quantizer layers, default all, decode): what the token space can represent at all,
    the ceiling of any generator on top of it. Returns a ``motion_for`` for
    :func:`controlmm.eval.cases.evaluate`; clips are cropped to a multiple of 4 frames."""
    tokenizer = model.parts.get("tokenizer")
    if not isinstance(tokenizer, RVQVAE):
        raise ControlMMError("this model directory has no tokenizer")
    total = tokenizer.cfg.num_quantizers
    if layers is not None and not 1 <= layers <= total:
        raise ControlMMError(f"layers must be between 1 and {total} for this tokenizer; got {layers}")
    dtype = next(tokenizer.parameters()).dtype

    def motion_for(case: ProbeCase) -> Motion:
        features = clip_features(data_dir, case.clip_id)
        n = len(features) // 4 * 4
        x = torch.as_tensor(
            model.normalizer.normalize(features[:n]), dtype=torch.float32, device=model.device
        )
        with torch.no_grad():
            ids = tokenizer.encode(x[None].to(dtype))
            out = tokenizer.decode(ids[..., :layers] if layers else ids)[0].float().cpu().numpy()
        return Motion.from_features(model.normalizer.denormalize(out))

    return motion_for
