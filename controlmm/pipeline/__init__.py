"""The plan pipeline: text + constraints + scene -> ControlMM -> retarget -> MuJoCo check -> feedback
-> export.

```python
from controlmm.pipeline import PlanConfig, plan, write_plan

result = plan(PlanConfig(scene="table"))        # the bundled example: a table and a hand target
print(result.report.summary())
write_plan(result, "out/plan")
```

- :class:`PlanConfig`: what to plan (scene, prompt, control, robot, seed, rounds, preset...);
- :func:`plan`: the generate/retarget/check loop with simulation feedback, -> :class:`PlanResult`;
- :func:`write_plan`: every output file, atomically;
- :func:`feedback_terms`, :class:`FeedbackConfig`: failures -> editing loss terms;
- :class:`StageTimes`: where a plan's time went (``result.timing``, ``report.json``'s ``timing``);
- :func:`retarget_checked`, :class:`CheckedTrajectory`: retargeting checked in MuJoCo, with
  fallback solver settings where the check fails (``controlmm retarget``, batch retarget jobs).
"""

from controlmm.pipeline.config import DEFAULT_SCENE, PlanConfig
from controlmm.pipeline.feedback import FeedbackConfig, feedback_terms
from controlmm.pipeline.outputs import write_plan
from controlmm.pipeline.plan import PlanResult, PlanRound, plan
from controlmm.pipeline.retarget_checked import CheckedTrajectory, retarget_checked
from controlmm.pipeline.timing import StageTimes

__all__ = [
    "DEFAULT_SCENE",
    "CheckedTrajectory",
    "FeedbackConfig",
    "PlanConfig",
    "PlanResult",
    "PlanRound",
    "StageTimes",
    "feedback_terms",
    "plan",
    "retarget_checked",
    "write_plan",
]
