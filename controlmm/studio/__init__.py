"""The planning studio: a browser app and an HTTP JSON API over a warm planning service.

```python
from controlmm.studio import PlanService, serve

service = PlanService("studio-plans")           # the model loads once, in the plan worker
serve(service, host="127.0.0.1", port=8080)     # the page at /, the API under /api/
```

- :class:`PlanService`, :class:`PlanJob`: the plan queue, its worker and its jobs;
- :func:`parse_plan_request`, :class:`RequestError`: a request's fields -> a checked ``PlanConfig``;
- :func:`plan_view`, :func:`dir_view`, :func:`scene_geometry`: what the browser viewer draws;
- :func:`make_app`, :func:`serve`: the aiohttp server (page, viewer, API on one port).

Needs the ``studio`` extra (aiohttp). CLI: ``controlmm studio``, ``controlmm view DIR``.
"""

from controlmm.studio.jobs import PlanJob, PlanService
from controlmm.studio.schema import FIELDS, PlanRequest, RequestError, parse_plan_request
from controlmm.studio.server import make_app, serve
from controlmm.studio.view import dir_view, is_plan_dir, plan_view, scene_geometry

__all__ = [
    "FIELDS",
    "PlanJob",
    "PlanRequest",
    "PlanService",
    "RequestError",
    "dir_view",
    "is_plan_dir",
    "make_app",
    "parse_plan_request",
    "plan_view",
    "scene_geometry",
    "serve",
]
