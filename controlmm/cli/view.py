"""``controlmm view DIR``: the studio's viewer over finished plans (no model loaded)."""

from __future__ import annotations

import argparse

from controlmm.cli.gl import import_mujoco
from controlmm.cli.studio import add_server_options, studio_extra_missing

HELP = """Serve the studio's 3-D viewer over finished plans, without loading a model.

DIR is a `controlmm plan` output (report.json, robot.npz, motion.npz, ...) or a folder whose
subfolders are plan outputs (a batch): each becomes a plan to pick in the page. The page shows the
robot in the scene in 3-D beside the human skeleton, with a timeline and play/pause, the failures
where they are, the constraint targets and where the joints got to, every round's figures, and the
files to download. The chosen round is drawn in 3-D (a plan folder keeps only its trajectory).
The JSON API answers as in `controlmm studio` (GET only)."""

EPILOG = """examples:
  controlmm plan --out out/plan && controlmm view out/plan      # then open http://127.0.0.1:8080/
  controlmm view out/batch --port 8090"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "view",
        help="the studio's 3-D viewer over finished plan outputs (no model loaded)",
        description=HELP,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("dir", metavar="DIR", help="a plan output, or a folder of plan outputs")
    add_server_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import_mujoco("egl")
    try:
        # heavy (MuJoCo, the scenes, aiohttp): imported when the command runs, so that --help stays fast
        from controlmm.studio.run import run_viewer
    except ModuleNotFoundError as exc:
        raise studio_extra_missing(exc) from None
    return run_viewer(args.dir, host=args.host, port=args.port)
