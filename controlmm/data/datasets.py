"""Torch datasets and the step-indexed batch sampler used by training.

Every random choice of an item (window start, caption, length rounding, crop) comes from a generator
seeded by ``(seed, epoch, index)``, and the order of items from ``(seed, epoch)``. A batch is therefore a
pure function of (seed, step): a resumed run, a run with more data-loading workers or a run split over
several processes sees exactly the batches of an uninterrupted single-process run.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import torch
from torch.utils.data import Dataset, Sampler

from controlmm.motion.normalization import Normalizer
from controlmm.motion.skeleton import MAX_FRAMES

Key = tuple[int, int]  # (item index, epoch)


def item_rng(seed: int, epoch: int, index: int) -> np.random.Generator:
    return np.random.default_rng([seed, epoch, index])


class WindowDataset(Dataset):
    """Random ``window``-frame crops of whole motions, normalised: (window, 263) float32 (tokenizer)."""

    def __init__(
        self, motions: Sequence[np.ndarray], normalizer: Normalizer, window: int, seed: int = 0
    ) -> None:
        self.motions = [m for m in motions if len(m) >= window]
        self.normalizer, self.window, self.seed = normalizer, window, seed

    def __len__(self) -> int:
        return len(self.motions)

    def __getitem__(self, key: Key) -> torch.Tensor:
        index, epoch = key
        motion = self.motions[index]
        start = int(item_rng(self.seed, epoch, index).integers(0, len(motion) - self.window + 1))
        window = self.normalizer.normalize(motion[start : start + self.window])
        return torch.from_numpy(np.ascontiguousarray(window, dtype=np.float32))


class TextMotionDataset(Dataset):
    """Captioned motions as the official text-to-motion loader serves them.

    Per item: a random caption; the length m rounded down to a multiple of ``unit`` (4), with
    probability 1/3 one more unit removed ("double"); a random crop of m frames; normalisation; zero
    padding to ``max_frames`` (196) **after** normalisation.

    Returns (motion (max_frames, 263) float32, m (int), caption index (int, into ``caption_index``)).
    """

    def __init__(
        self,
        samples: Sequence,
        normalizer: Normalizer,
        caption_index: dict[str, int],
        unit: int = 4,
        max_frames: int = MAX_FRAMES,
        seed: int = 0,
    ) -> None:
        self.samples = list(samples)
        self.normalizer, self.caption_index = normalizer, caption_index
        self.unit, self.max_frames, self.seed = unit, max_frames, seed
        self.lengths = [min(s.length, max_frames) for s in self.samples]  # frames, for length bucketing

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, key: Key) -> tuple[torch.Tensor, int, int]:
        index, epoch = key
        sample = self.samples[index]
        rng = item_rng(self.seed, epoch, index)
        caption = sample.captions[int(rng.integers(len(sample.captions)))]
        units = min(sample.length, self.max_frames) // self.unit
        if rng.integers(3) == 2:  # 'single', 'single', 'double'
            units -= 1
        m = units * self.unit
        start = int(rng.integers(0, sample.length - m + 1))
        motion = np.zeros((self.max_frames, sample.motion.shape[1]), dtype=np.float32)
        motion[:m] = self.normalizer.normalize(sample.motion[start : start + m])
        return torch.from_numpy(motion), m, self.caption_index[caption]


class StepBatchSampler(Sampler):
    """Yields, for steps ``start_step .. end_step-1`` of one epoch, this process's share of each batch.

    The epoch's order is a permutation seeded by (seed, epoch); step s takes items
    [s*B, (s+1)*B) of it (incomplete last batch dropped) and process ``rank`` of ``world`` takes every
    world-th of those. Items are ``(index, epoch)`` keys for the datasets above.

    Length bucketing (``bucket`` > 0 with ``lengths``, one per item): each run of ``bucket`` consecutive
    batches of that order is sorted by length and cut into batches again, and the epoch's batches are
    shuffled (seeded by (seed, epoch)). Every item is still seen once per epoch, but a batch holds clips
    of similar length, so trimming it to its longest clip saves the padded positions' compute.
    """

    def __init__(
        self,
        num_items: int,
        batch_size: int,
        seed: int,
        epoch: int,
        start_step: int = 0,
        end_step: int | None = None,
        rank: int = 0,
        world: int = 1,
        shuffle: bool = True,
        lengths: Sequence[int] | None = None,
        bucket: int = 0,
    ) -> None:
        self.num_items, self.batch_size, self.seed, self.epoch = num_items, batch_size, seed, epoch
        self.rank, self.world, self.shuffle = rank, world, shuffle
        self.steps_per_epoch = num_items // batch_size
        self.start_step = start_step
        self.end_step = self.steps_per_epoch if end_step is None else min(end_step, self.steps_per_epoch)
        if bucket > 0 and (lengths is None or len(lengths) != num_items):
            raise ValueError(
                f"length bucketing needs one length per item ({num_items}); got "
                f"{'none' if lengths is None else len(lengths)}"
            )
        self.lengths, self.bucket = lengths, bucket

    def __len__(self) -> int:
        return max(0, self.end_step - self.start_step)

    def batches(self) -> list[np.ndarray]:
        """The epoch's batches of item indices, in step order (all processes' shares)."""
        rng = np.random.default_rng([self.seed, self.epoch, 7919])
        order = rng.permutation(self.num_items) if self.shuffle else np.arange(self.num_items)
        b = self.batch_size
        order = order[: self.steps_per_epoch * b]
        if self.bucket <= 0:
            return [order[s * b : (s + 1) * b] for s in range(self.steps_per_epoch)]
        lengths = np.asarray(self.lengths)
        batches = []
        for start in range(0, len(order), self.bucket * b):
            group = order[start : start + self.bucket * b]
            group = group[np.argsort(lengths[group], kind="stable")]
            batches += [group[i : i + b] for i in range(0, len(group), b)]
        return [batches[i] for i in rng.permutation(len(batches))] if self.shuffle else batches

    def __iter__(self) -> Iterator[list[Key]]:
        batches = self.batches()
        for step in range(self.start_step, self.end_step):
            yield [(int(i), self.epoch) for i in batches[step][self.rank :: self.world]]
