"""Batches: many plan / retarget / validate jobs on a local process pool or Ray, resumable.

```python
from controlmm.batch import BatchConfig, load_jobs, run_batch

jobs = load_jobs("jobs.jsonl")                   # or a folder of motions: load_jobs("motions/", ["g1", "h1"])
result = run_batch(jobs, "out/batch", BatchConfig(workers=2, timeout_s=600))
result.counts                                    # {"jobs", "passed", "failed", "error", ..., "pass_rate"}
```

- :mod:`~controlmm.batch.jobs`: :class:`Job`, scene variations; :mod:`~controlmm.batch.sources`: JSONL
  files and folders of motions;
- :mod:`~controlmm.batch.runner`: :func:`run_batch` and :class:`BatchConfig`;
- :mod:`~controlmm.batch.pool` / :mod:`~controlmm.batch.ray_backend`: the local pool and Ray (optional);
- :mod:`~controlmm.batch.worker` / :mod:`~controlmm.batch.tasks`: what runs in a worker;
- :mod:`~controlmm.batch.store` / :mod:`~controlmm.batch.summary`: the batch folder and its summary.
"""

from controlmm.batch.jobs import Job, scene_variations
from controlmm.batch.runner import BatchConfig, BatchResult, run_batch
from controlmm.batch.sources import duplicate_ids, folder_jobs, load_jobs, read_jsonl
from controlmm.batch.store import BatchStore
from controlmm.batch.summary import write_summary

__all__ = [
    "BatchConfig",
    "BatchResult",
    "BatchStore",
    "Job",
    "duplicate_ids",
    "folder_jobs",
    "load_jobs",
    "read_jsonl",
    "run_batch",
    "scene_variations",
    "write_summary",
]
