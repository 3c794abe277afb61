"""The studio's HTTP server (aiohttp): the page, its viewer, and the JSON API on one port.

=======================================  =================================================================
route                                    answer
=======================================  =================================================================
``GET /``                                the studio page (``view`` mode: the viewer over finished plans)
``GET /static/{file}``                   the page's script and style (shipped in the package)
``GET /api/info``                        mode, model state, scenes, robots, joints, presets, defaults
``GET /api/scene?scene=S&robot=R``       a scene to place targets in: geometry id, start, suggestions
``POST /api/spec``                       ``{"scene", "robot", "control"}`` -> the spec's targets (world m)
``POST /api/plans``                      plan fields (``PlanConfig``) -> ``{"id"}``, HTTP 202
``GET /api/plans``                       every plan: id, status
``GET /api/plans/{id}``                  ``{"status": queued|running|done|failed, "progress", "report"}``
``GET /api/plans/{id}/view``             the viewer's document of a done plan (every round)
``GET /api/plans/{id}/files/{name}``     an output file (``report.json``, ``robot.csv``, ``plots/...``)
``GET /api/geometry/{id}``               a scene's drawn geometry (meshes, colours, static poses)
=======================================  =================================================================

Bad input answers HTTP 400 with ``{"error": one line, "field": the bad field}``; the server goes
on. It binds to 127.0.0.1 unless told otherwise.
"""

from __future__ import annotations

import asyncio
import json
import math
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import web

from controlmm.control.spec import ControlSpec
from controlmm.editing.presets import PRESETS
from controlmm.errors import ControlMMError
from controlmm.motion.skeleton import FPS, JOINT_NAMES, MAX_FRAMES
from controlmm.pipeline import DEFAULT_SCENE, PlanConfig
from controlmm.studio.jobs import PlanService
from controlmm.studio.schema import FIELDS, SERVICE_DEFAULTS, RequestError, parse_plan_request, parse_spec
from retarget import available_robots, load_robot, robot_scale
from scenes import list_scenes, load_scene

WEB = resources.files("controlmm.studio") / "web"
STATIC = {"studio.js": "text/javascript", "viewer.js": "text/javascript", "studio.css": "text/css"}
SERVICE: web.AppKey[PlanService] = web.AppKey("service", PlanService)
MODE: web.AppKey[str] = web.AppKey("mode", str)


def _error(status: int, message: str, field: str | None = None) -> web.Response:
    body: dict[str, Any] = {"error": message}
    if field is not None:
        body["field"] = field
    return web.json_response(body, status=status)


async def _in_thread(func, *args):
    """Run blocking work (scene compiles, view building) off the event loop: the page stays live."""
    return await asyncio.get_running_loop().run_in_executor(None, func, *args)


async def page(request: web.Request) -> web.Response:
    html = (WEB / "index.html").read_text(encoding="utf-8")
    return web.Response(text=html.replace("{{MODE}}", request.app[MODE]), content_type="text/html")


async def static(request: web.Request) -> web.Response:
    name = request.match_info["name"]
    if name not in STATIC:
        return _error(404, f"no static file '{name}'")
    return web.Response(text=(WEB / name).read_text(encoding="utf-8"), content_type=STATIC[name])


async def info(request: web.Request) -> web.Response:
    service = request.app[SERVICE]
    defaults = {k: v for k, v in PlanConfig().to_dict().items() if k in FIELDS}
    defaults.update(SERVICE_DEFAULTS)
    return web.json_response(
        {
            "mode": request.app[MODE],
            "model": service.model_state,
            "model_error": service.model_error,
            "scenes": list_scenes(),
            "default_scene": DEFAULT_SCENE,
            "robots": available_robots(),
            "joints": list(JOINT_NAMES),
            "presets": list(PRESETS),
            "fps": FPS,
            "max_frames": MAX_FRAMES,
            "fields": list(FIELDS),
            "defaults": defaults,
        }
    )


def _scene_doc(service: PlanService, scene_ref: str, robot: str) -> dict[str, Any]:
    try:
        load_robot(robot)
    except ControlMMError as exc:
        raise RequestError("robot", str(exc)) from None
    try:
        scene, gid = service.preview(scene_ref, robot)
    except ControlMMError as exc:
        raise RequestError("scene", str(exc)) from None
    targets: list[dict[str, Any]] = []
    if scene.suggested_control:
        transform = scene.human_to_world(robot_scale(robot))
        targets = _targets(ControlSpec.from_dict(scene.suggested_control), transform)
    return {
        "scene": scene.name,
        "robot": robot,
        "geometry": gid,
        "description": scene.description,
        "suggested_prompt": scene.suggested_prompt,
        "suggested_targets": targets,
        "start": {"x": scene.start.x, "y": scene.start.y, "yaw": scene.start.yaw},
    }


def _targets(spec: ControlSpec, transform) -> list[dict[str, Any]]:
    world = transform.to_world(spec.human_positions(transform))
    return [
        {"joint": c.joint_name, "frame": c.frame, "position": [round(float(v), 4) for v in p]}
        for c, p in zip(spec.constraints, world, strict=True)
    ]


async def scene(request: web.Request) -> web.Response:
    service = request.app[SERVICE]
    scene_ref = request.query.get("scene", DEFAULT_SCENE).strip() or DEFAULT_SCENE
    robot = request.query.get("robot", "g1").strip() or "g1"
    try:
        return web.json_response(await _in_thread(_scene_doc, service, scene_ref, robot))
    except RequestError as exc:
        return _error(400, str(exc), exc.field)


def _spec_targets(body: dict[str, Any]) -> dict[str, Any]:
    spec = parse_spec(body.get("control"))
    robot = str(body.get("robot") or "g1")
    try:
        load_robot(robot)
    except ControlMMError as exc:
        raise RequestError("robot", str(exc)) from None
    try:
        scene = load_scene(str(body.get("scene") or DEFAULT_SCENE), robot=robot)
    except ControlMMError as exc:
        raise RequestError("scene", str(exc)) from None
    if spec.last_frame >= MAX_FRAMES:
        raise RequestError(
            "control",
            f"a constraint at frame {spec.last_frame} is past the longest motion "
            f"(frames 0..{MAX_FRAMES - 1})",
        )
    return {"targets": _targets(spec, scene.human_to_world(robot_scale(robot)))}


async def spec(request: web.Request) -> web.Response:
    body = await _json(request)
    if isinstance(body, web.Response):
        return body
    if not isinstance(body, dict):
        return _error(400, "the body must be a JSON object: {scene, robot, control}")
    try:
        return web.json_response(await _in_thread(_spec_targets, body))
    except RequestError as exc:
        return _error(400, str(exc), exc.field)


async def _json(request: web.Request) -> Any:
    try:
        return json.loads(await request.text(), parse_constant=_reject_constant)
    except (json.JSONDecodeError, ValueError) as exc:
        return _error(400, f"the request body is not JSON: {exc}")


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number JSON allows")


async def create_plan(request: web.Request) -> web.Response:
    service = request.app[SERVICE]
    if request.app[MODE] != "studio":
        return _error(405, "this server views finished plans (controlmm view); plan with controlmm studio")
    body = await _json(request)
    if isinstance(body, web.Response):
        return body
    try:
        parsed = await _in_thread(parse_plan_request, body, service.model_dir)
        job = service.submit(parsed)
    except RequestError as exc:
        return _error(400, str(exc), exc.field)
    except ControlMMError as exc:
        return _error(503, str(exc))
    return web.json_response({"id": job.id}, status=202)


async def list_plans(request: web.Request) -> web.Response:
    jobs = request.app[SERVICE].jobs()
    return web.json_response({"plans": [j.to_dict(report=False) for j in jobs]})


def _job(request: web.Request):
    job = request.app[SERVICE].get(request.match_info["id"])
    if job is None:
        raise web.HTTPNotFound(
            text=json.dumps({"error": f"no plan '{request.match_info['id']}'"}),
            content_type="application/json",
        )
    return job


async def get_plan(request: web.Request) -> web.Response:
    return web.json_response(_job(request).to_dict(), dumps=_dumps)


def _dumps(obj: Any) -> str:
    return json.dumps(_finite(obj), allow_nan=False)


def _finite(obj: Any) -> Any:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    return obj


async def plan_view(request: web.Request) -> web.Response:
    service, job = request.app[SERVICE], _job(request)
    try:
        body = await _in_thread(service.view_json, job)
    except ControlMMError as exc:
        return _error(409 if job.status != "done" else 400, str(exc))
    return web.Response(body=body, content_type="application/json")


async def plan_file(request: web.Request) -> web.StreamResponse:
    job = _job(request)
    name = request.match_info["name"]
    if job.status != "done" or job.out_dir is None:
        return _error(409, f"plan '{job.id}' is {job.status}; its files come when it is done")
    if name not in job.files:
        return _error(404, f"plan '{job.id}' has no file '{name}'; files: {', '.join(job.files)}")
    path = Path(job.out_dir) / name
    headers = {"Content-Disposition": f'attachment; filename="{Path(name).name}"'}
    if name.endswith((".png", ".mp4", ".json")):
        headers = {}
    return web.FileResponse(path, headers=headers)


async def geometry(request: web.Request) -> web.Response:
    body = request.app[SERVICE].geometry_json(request.match_info["id"])
    if body is None:
        return _error(404, f"no geometry '{request.match_info['id']}'")
    return web.Response(body=body, content_type="application/json", headers={"Cache-Control": "max-age=3600"})


def make_app(service: PlanService, mode: str = "studio") -> web.Application:
    """The aiohttp application of a :class:`PlanService` (``mode``: ``studio`` or ``view``)."""
    app = web.Application(client_max_size=8 * 1024 * 1024)
    app[SERVICE] = service
    app[MODE] = mode
    app.router.add_get("/", page)
    app.router.add_get("/static/{name}", static)
    app.router.add_get("/api/info", info)
    app.router.add_get("/api/scene", scene)
    app.router.add_post("/api/spec", spec)
    app.router.add_post("/api/plans", create_plan)
    app.router.add_get("/api/plans", list_plans)
    app.router.add_get("/api/plans/{id}", get_plan)
    app.router.add_get("/api/plans/{id}/view", plan_view)
    app.router.add_get("/api/plans/{id}/files/{name:.+}", plan_file)
    app.router.add_get("/api/geometry/{id}", geometry)
    return app


def serve(
    service: PlanService,
    host: str = "127.0.0.1",
    port: int = 8080,
    mode: str = "studio",
    on_ready=None,
) -> None:
    """Serve until interrupted (Ctrl-C). ``on_ready(url)`` is called once the port is bound
    (``port=0`` picks a free one)."""

    async def main() -> None:
        runner = web.AppRunner(make_app(service, mode), access_log=None, shutdown_timeout=2.0)
        await runner.setup()
        site = web.TCPSite(runner, host, port)
        try:
            await site.start()
        except OSError as exc:
            await runner.cleanup()
            raise ControlMMError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
        bound = runner.addresses[0][1] if runner.addresses else port
        shown = f"[{host}]" if ":" in host else host
        if on_ready is not None:
            on_ready(f"http://{shown}:{bound}/")
        try:
            await asyncio.Event().wait()
        finally:
            await runner.cleanup()

    asyncio.run(main())
