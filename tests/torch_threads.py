"""One torch thread for tiny-model tests (fastest for them, and immune to other processes' load)."""

from __future__ import annotations

import contextlib

import torch


@contextlib.contextmanager
def one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)
