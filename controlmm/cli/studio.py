"""``controlmm studio``: the planning studio in the browser, over a warm planning service."""

from __future__ import annotations

import argparse

from controlmm.cli.args import add_threads, integer
from controlmm.cli.gl import import_mujoco
from controlmm.errors import ControlMMError

HELP = """Serve the planning studio: a browser page and an HTTP JSON API with the models loaded once.

In the page: pick a scene (bundled, or an MJCF path on this machine) and a robot, type a prompt,
place joint targets (joint, frame, world position; click in the 3-D view to move one) or load a
control spec, and plan. Each round's progress shows while it runs; then the robot moves in the
scene in 3-D beside the human skeleton, with a timeline and play/pause, the failures drawn where
they are (the penetrating body in red at its frames, contact points, the clearance curve), the
rounds side by side, each target and where its joint got to, and the output files to download.

The same port answers the JSON API (README: Planning studio):
  POST /api/plans {"scene": "table", "text": "...", "control": {...}, "seed": 0, ...} -> {"id": ...}
  GET  /api/plans/ID              -> {"status": "queued"|"running"|"done"|"failed", "report": {...}}
  GET  /api/plans/ID/files/NAME   -> an output file (robot.csv, report.json, plots/top_view.png, ...)
Plans run one at a time in a worker; their files live in a temporary folder removed when the
studio stops (download what you keep). It listens on 127.0.0.1 unless --host says otherwise."""

EPILOG = """examples:
  controlmm studio                       # then open http://127.0.0.1:8080/
  controlmm studio --port 8090 --model models/official
  curl -s -X POST localhost:8080/api/plans -d '{"scene": "pillars", "seed": 3}'
finished plans without a model: controlmm view DIR"""


def add_server_options(p: argparse.ArgumentParser) -> None:
    """``--port`` and ``--host`` (shared with ``controlmm view``)."""
    p.add_argument(
        "--port", type=integer(0, 65535), default=8080, help="TCP port (default 8080; 0 picks a free one)"
    )
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1: this machine only; 0.0.0.0 opens it to the network)",
    )


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "studio",
        help="the planning studio in the browser, with an HTTP JSON API (models loaded once)",
        description=HELP,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_server_options(p)
    p.add_argument("--model", default=None, help="model directory (default: the embedded default model)")
    add_threads(p, 1, "; as for controlmm plan")
    p.set_defaults(func=run)


def studio_extra_missing(exc: ModuleNotFoundError) -> ControlMMError:
    """The one-line error when the ``studio`` extra (aiohttp) is not installed."""
    if exc.name != "aiohttp":
        raise exc
    return ControlMMError("the studio needs the 'studio' extra (aiohttp): pip install -e '.[studio]'")


def run(args: argparse.Namespace) -> int:
    import_mujoco("egl")
    try:
        # heavy (torch, MuJoCo, aiohttp): imported when the command runs, so that --help stays fast
        from controlmm.studio.run import run_studio
    except ModuleNotFoundError as exc:
        raise studio_extra_missing(exc) from None
    return run_studio(host=args.host, port=args.port, model=args.model, threads=args.threads)
