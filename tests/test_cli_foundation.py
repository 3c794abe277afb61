"""The console script end to end: convert, plot, info, --help, bad input (exit 2, one line)."""

import subprocess
import sys

import numpy as np
import pytest
from cli_helpers import in_process

from controlmm.cli.main import SUBCOMMANDS
from controlmm.motion.bvh import read_bvh


def run(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "controlmm", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=600,
    )


def test_version_and_help(capsys):
    out = run("--version")  # the real console entry point, once
    assert out.returncode == 0 and out.stdout.startswith("controlmm ")
    from controlmm.cli.main import main

    for name in SUBCOMMANDS:  # every subcommand's --help, in-process (a subprocess each costs seconds)
        with pytest.raises(SystemExit) as exc:
            main([name.replace("_", "-"), "--help"])  # module import_official -> command import-official
        assert exc.value.code == 0, name
        assert "usage: controlmm" in capsys.readouterr().out


def test_convert_features_to_npz_and_bvh(tmp_path, humanml3d_dir, sample_joints):
    src = humanml3d_dir / "new_joint_vecs" / "012314.npy"
    res = in_process("convert", src, tmp_path / "m.npz")
    assert res.returncode == 0, res.stderr
    with np.load(tmp_path / "m.npz") as data:
        assert np.abs(data["joints"] - sample_joints).max() < 1e-4
    res = in_process("convert", src, tmp_path / "m.bvh")
    assert res.returncode == 0, res.stderr
    joints, _ = read_bvh(tmp_path / "m.bvh")
    assert np.linalg.norm(joints - sample_joints, axis=-1).max() < 0.01


def test_plot_png_and_animation(tmp_path, humanml3d_dir):
    src = humanml3d_dir / "new_joint_vecs" / "012314.npy"
    short = tmp_path / "short.npy"
    np.save(short, np.load(src)[:30])
    for name in ("m.png", "m.gif", "m.mp4"):
        res = in_process("plot", short, "--out", tmp_path / name)
        assert res.returncode == 0, res.stderr
        assert (tmp_path / name).stat().st_size > 1000
    assert (tmp_path / "m.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_info():
    res = run("info")
    assert res.returncode == 0
    assert "torch" in res.stdout and "robots" in res.stdout and "g1" in res.stdout


@pytest.mark.parametrize(
    "make_args,needle",
    [
        (lambda d: ["convert", d / "missing.npy", d / "o.npz"], "does not exist"),
        (lambda d: ["convert", d / "bad_shape.npy", d / "o.npz"], "shape"),
        (lambda d: ["convert", d / "nan.npy", d / "o.npz"], "NaN"),
        (lambda d: ["convert", d / "ok.npy", d / "o.xyz"], "allowed"),
        (lambda d: ["convert", d / "ok.txt", d / "o.npz"], "allowed"),
        (lambda d: ["convert", d / "ok.npy", d / "ok.txt" / "o.npz"], "is not a directory"),
        (lambda d: ["plot", d / "ok.npy", "--out", d / "o.jpg"], "allowed"),
        (lambda d: ["convert"], "required"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, make_args, needle):
    np.save(tmp_path / "bad_shape.npy", np.zeros((5, 7)))
    nan = np.zeros((5, 22, 3))
    nan[2, 3, 1] = np.nan
    np.save(tmp_path / "nan.npy", nan)
    np.save(tmp_path / "ok.npy", np.zeros((5, 22, 3)))
    (tmp_path / "ok.txt").write_text("x")
    before = set(tmp_path.iterdir())
    res = in_process(*make_args(tmp_path))
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], res.stderr
    assert "Traceback" not in res.stderr
    assert set(tmp_path.iterdir()) == before  # nothing half-written


def test_unwritable_output_exits_2(tmp_path, humanml3d_dir):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        res = run("convert", humanml3d_dir / "new_joints" / "012314.npy", locked / "o.npz")
        import os

        if os.geteuid() == 0:  # root ignores directory permissions; the check is still one line
            assert res.returncode in (0, 2)
        else:
            assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    finally:
        locked.chmod(0o700)
