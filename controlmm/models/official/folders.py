"""Finding the official checkpoint folders on disk (MoMask / MaskControl ``checkpoints/t2m`` layout).

After the official download scripts, ``checkpoints/t2m/`` holds one folder per model::

    rvq_nq6_dc512_nc512_noshare_qdp0.2/            RVQ-VAE: model/net_best_fid.tar, meta/{mean,std}.npy,
                                                   opt.txt
    t2m_nlayer8_nhead6_ld384_ff1024_cdp0.1_rvq6ns/ masked transformer: model/latest.tar
                                                   (+ net_best_fid.tar), opt.txt
    tres_nlayer8_ld384_ff1024_rvq6ns_cdp0.2_sw/    residual transformer: model/net_best_fid.tar, opt.txt
    z2024-08-23-01-27-51_CtrlNet_..._fixRandCond/  MaskControl, pelvis only: model/latest.tar, opt.txt
    z2024-08-27-21-07-55_CtrlNet_..._cross/        MaskControl, all joints: model/latest.tar, opt.txt

``--momask`` may name the checkout root, its ``checkpoints/``, or ``checkpoints/t2m``. Within it the
released folder names are preferred; otherwise the one folder whose name starts with ``rvq``,
``t2m_`` or ``tres_`` is used. ``--control`` names one control run folder (or its ``.tar``).
The checkpoint file of each folder is the one the official scripts load (VQ and residual:
``net_best_fid.tar``; masked transformer: ``latest.tar``, as MoMask ``gen_t2m.py`` and MaskControl
``train_ctrlnet.py``; control: ``latest.tar``), falling back to the other when absent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from controlmm.errors import InputFileError
from controlmm.models.official.opt import read_opt

RELEASED_NAMES: dict[str, str] = {
    "tokenizer": "rvq_nq6_dc512_nc512_noshare_qdp0.2",
    "transformer": "t2m_nlayer8_nhead6_ld384_ff1024_cdp0.1_rvq6ns",
    "residual": "tres_nlayer8_ld384_ff1024_rvq6ns_cdp0.2_sw",
}
"""The released MoMask HumanML3D folders (``humanml3d_models.zip``)."""

RELEASED_CONTROL_NAMES: dict[str, str] = {
    "pelvis": "z2024-08-23-01-27-51_CtrlNet_randCond1-196_l1.1XEnt.9TTT__fixRandCond",
    "all": "z2024-08-27-21-07-55_CtrlNet_randCond1-196_l1.5XEnt.5TTT__cross",
}
"""The released MaskControl runs: pelvis-only (6 control channels) and all joints (36)."""

NAME_PREFIXES = {"tokenizer": "rvq", "transformer": "t2m_", "residual": "tres_"}
CHECKPOINT_FILES: dict[str, tuple[str, ...]] = {
    "tokenizer": ("net_best_fid.tar", "latest.tar"),
    "transformer": ("latest.tar", "net_best_fid.tar"),
    "residual": ("net_best_fid.tar", "latest.tar"),
    "control": ("latest.tar", "net_best_acc.tar"),
}


@dataclass(frozen=True)
class OfficialFolder:
    """One official model folder: its checkpoint file and its parsed ``opt.txt`` ({} when absent)."""

    kind: str
    folder: Path
    checkpoint: Path
    opt: dict[str, Any] = field(default_factory=dict)

    @property
    def has_opt(self) -> bool:
        return bool(self.opt)


def _t2m_dirs(root: Path) -> list[Path]:
    return list(dict.fromkeys([root, root / "t2m", root / "checkpoints" / "t2m"]))


def _checkpoint(kind: str, folder: Path) -> Path | None:
    return next(
        (folder / "model" / name for name in CHECKPOINT_FILES[kind] if (folder / "model" / name).is_file()),
        None,
    )


def _folder(kind: str, folder: Path) -> OfficialFolder:
    checkpoint = _checkpoint(kind, folder)
    if checkpoint is None:
        raise InputFileError(f"'{folder}' has no model/{' or model/'.join(CHECKPOINT_FILES[kind])}")
    opt_path = folder / "opt.txt"
    return OfficialFolder(kind, folder, checkpoint, read_opt(opt_path) if opt_path.is_file() else {})


def find_momask(root: str | Path) -> dict[str, OfficialFolder]:
    """The RVQ-VAE, masked and residual transformer folders under ``root`` (see the module docstring)."""
    root = Path(root).expanduser()
    if not root.is_dir():
        raise InputFileError(f"--momask '{root}' is not a directory")
    dirs = [d for d in _t2m_dirs(root) if d.is_dir()]
    found: dict[str, OfficialFolder] = {}
    for kind, released in RELEASED_NAMES.items():
        exact = next((d / released for d in dirs if (d / released).is_dir()), None)
        if exact is not None:
            found[kind] = _folder(kind, exact)
            continue
        candidates = sorted(
            {
                c
                for d in dirs
                for c in d.iterdir()
                if c.is_dir() and c.name.startswith(NAME_PREFIXES[kind]) and _checkpoint(kind, c)
            }
        )
        if len(candidates) != 1:
            what = "none" if not candidates else ", ".join(c.name for c in candidates)
            raise InputFileError(
                f"--momask '{root}': expected one {kind} folder '{released}' (or one "
                f"'{NAME_PREFIXES[kind]}*' folder with model/{CHECKPOINT_FILES[kind][0]}) in "
                f"{', '.join(str(d) for d in dirs) or root}; found {what}"
            )
        found[kind] = _folder(kind, candidates[0])
    meta = found["tokenizer"].folder / "meta"
    for name in ("mean.npy", "std.npy"):
        if not (meta / name).is_file():
            raise InputFileError(
                f"'{meta / name}' is missing: the RVQ-VAE folder's normalisation (MoMask saves it "
                "with the VQ checkpoint; the transformers use the same file)"
            )
    return found


def find_control(path: str | Path) -> OfficialFolder:
    """The MaskControl run folder named by ``path`` (the folder, its ``model/``, or the ``.tar`` file)."""
    path = Path(path).expanduser()
    if path.is_file():
        folder = path.parent.parent if path.parent.name == "model" else path.parent
        opt_path = folder / "opt.txt"
        return OfficialFolder("control", folder, path, read_opt(opt_path) if opt_path.is_file() else {})
    if not path.is_dir():
        raise InputFileError(f"--control '{path}' does not exist")
    if path.name == "model" and _checkpoint("control", path.parent):
        path = path.parent
    if _checkpoint("control", path):
        return _folder("control", path)
    runs = sorted(
        c
        for c in path.iterdir()
        if c.is_dir() and _checkpoint("control", c) and not c.name.startswith(tuple(NAME_PREFIXES.values()))
    )
    if len(runs) == 1:
        return _folder("control", runs[0])
    if runs:
        raise InputFileError(
            f"--control '{path}' holds several control runs ({', '.join(r.name for r in runs)}); "
            "name one of them"
        )
    raise InputFileError(
        f"--control '{path}' has no model/latest.tar (expected a MaskControl run folder such as "
        f"'{RELEASED_CONTROL_NAMES['all']}')"
    )
