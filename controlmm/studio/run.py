"""Starting the server from the command line: ``controlmm studio`` and ``controlmm view``.

Both print one line with the address once the port is bound (``controlmm studio: serving
http://127.0.0.1:8080/``), serve until Ctrl-C or SIGTERM, and then stop cleanly (exit 0).
"""

from __future__ import annotations

import ipaddress
import signal
import sys
import tempfile
from pathlib import Path

from controlmm.errors import ControlMMError
from controlmm.studio.jobs import PlanService
from controlmm.studio.server import serve
from controlmm.studio.view import is_plan_dir


def _announce(command: str, host: str, note: str = ""):
    def ready(url: str) -> None:
        print(f"controlmm {command}: serving {url} (Ctrl-C to stop){note}", flush=True)
        if not _loopback(host):
            print(
                f"controlmm {command}: warning: listening on {host}: anyone who reaches this machine "
                "can use the studio",
                file=sys.stderr,
                flush=True,
            )

    return ready


def _loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _stop_on_sigterm() -> None:
    def stop(signum, frame) -> None:  # SIGTERM ends the server like Ctrl-C: cleanly
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)


def run_studio(host: str = "127.0.0.1", port: int = 8080, model: str | None = None, threads: int = 1) -> int:
    """Serve the studio with the model loaded once (in the plan worker); returns the exit status."""
    if model is not None and not Path(model).is_dir():
        raise ControlMMError(f"model directory '{model}' does not exist")
    _stop_on_sigterm()
    with tempfile.TemporaryDirectory(prefix="controlmm-studio-") as workdir:
        service = PlanService(workdir, model=model, threads=threads)
        try:
            serve(service, host, port, "studio", _announce("studio", host, "; the model loads in the worker"))
        except KeyboardInterrupt:
            print("controlmm studio: stopped", file=sys.stderr)
        finally:
            service.close(timeout=1.0)
    return 0


def plan_dirs(path: str | Path) -> list[Path]:
    """The plan outputs in ``path``: itself, or its subfolders that are plan outputs (a batch)."""
    root = Path(path)
    if not root.is_dir():
        raise ControlMMError(f"'{root}' is not a directory (give a plan output folder)")
    if is_plan_dir(root):
        return [root]
    found = sorted(p for p in root.iterdir() if p.is_dir() and is_plan_dir(p))
    if not found:
        raise ControlMMError(
            f"'{root}' is not a plan output (report.json, robot.npz, motion.npz) nor a folder of them"
        )
    return found


def run_viewer(path: str | Path, host: str = "127.0.0.1", port: int = 8080) -> int:
    """Serve the viewer over the plan outputs in ``path`` (no model loaded); returns the exit status."""
    dirs = plan_dirs(path)
    _stop_on_sigterm()
    with tempfile.TemporaryDirectory(prefix="controlmm-view-") as workdir:
        service = PlanService(workdir, load=False)
        for d in dirs:
            service.add_finished(d)
        try:
            serve(service, host, port, "view", _announce("view", host, f"; {len(dirs)} plan(s)"))
        except KeyboardInterrupt:
            print("controlmm view: stopped", file=sys.stderr)
    return 0
