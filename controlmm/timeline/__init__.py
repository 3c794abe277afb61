"""Body-part timeline control: several prompts, each for a body part and a time span (paper A.9).

```python
from controlmm.generate import load_model
from controlmm.timeline import Timeline, Track, generate_timeline

timeline = Timeline([Track("legs", "a person walks forward", 0, 6),
                     Track("right_arm", "a person waves the right hand", 2, 4)])
motion, report = generate_timeline(load_model(), timeline, seed=0)
report["max_drift_cm"], report["max_boundary_speed_mps"]
```

See ``docs/timeline.md`` for the spec format, the body-part table and the algorithm.
"""

from controlmm.timeline.algorithm import as_timeline, generate_timeline
from controlmm.timeline.parts import BODY_PARTS, moves_root, part_joints, part_name
from controlmm.timeline.signals import (
    ControlSignal,
    Entries,
    boundary_speed,
    build_signal,
    held_drift,
    signal_terms,
)
from controlmm.timeline.spec import Timeline, Track

__all__ = [
    "BODY_PARTS",
    "ControlSignal",
    "Entries",
    "Timeline",
    "Track",
    "as_timeline",
    "boundary_speed",
    "build_signal",
    "generate_timeline",
    "held_drift",
    "moves_root",
    "part_joints",
    "part_name",
    "signal_terms",
]
