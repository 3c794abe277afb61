"""``controlmm scene list|show|sdf``: outputs and one-line errors with exit code 2."""

from __future__ import annotations

import subprocess
import sys

import pytest

from controlmm.cli.main import SUBCOMMANDS
from tests.cli_helpers import run_cli


def run(*args):
    return subprocess.run(
        [sys.executable, "-m", "controlmm", *map(str, args)], capture_output=True, text=True, timeout=300
    )


def test_scene_is_a_subcommand_and_list_names_every_scene(capsys):
    assert "scene" in SUBCOMMANDS
    assert run_cli(["scene", "list", "-v"]) == 0
    out = capsys.readouterr().out
    for name in (
        "empty",
        "corridor",
        "pillars",
        "table",
        "low_beam",
        "doorway",
        "moving_obstacle",
        "mesh_rock",
    ):
        assert name in out
    assert "prompt :" in out and '"coords": "world"' in out


def test_show_renders_with_mujoco_egl(tmp_path):
    res = run("scene", "show", "table", "--out", tmp_path / "t.png", "--width", "160", "--height", "120")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "t.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_show_falls_back_to_matplotlib_without_gl(tmp_path, capsys, monkeypatch):
    import mujoco

    def no_gl(*args, **kwargs):
        raise RuntimeError("no OpenGL context")

    monkeypatch.setattr(mujoco, "Renderer", no_gl)  # as on a machine where no GL backend loads
    assert (
        run_cli(["scene", "show", "moving_obstacle", "--out", str(tmp_path / "m.png"), "--time", "2.5"]) == 0
    )
    out = capsys.readouterr().out
    assert "MuJoCo rendering failed" in out and "no OpenGL context" in out and "matplotlib" in out
    assert (tmp_path / "m.png").stat().st_size > 10_000


def test_sdf_slice(tmp_path, capsys):
    assert run_cli(["scene", "sdf", "low_beam", "--out", str(tmp_path / "s.png"), "--height", "1.05"]) == 0
    assert (tmp_path / "s.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    "args,needle",
    [
        (["scene", "show", "nowhere", "--out", "{d}/x.png"], "known scenes: empty, corridor"),
        (["scene", "sdf", "{d}/bad.xml", "--out", "{d}/x.png"], "line 3"),
        (["scene", "sdf", "low_beam", "--out", "{d}/x.jpg"], "allowed: .png"),
        (["scene", "sdf", "low_beam", "--out", "{d}/x.png", "--height", "nan"], "finite"),
        (["scene", "show", "low_beam", "--out", "{d}/x.png", "--robot", "r2d2"], "unknown robot"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, capsys, args, needle):
    (tmp_path / "bad.xml").write_text(
        '<mujoco>\n<worldbody>\n<geom type="boxx" size="1 1 1"/>\n</worldbody>\n</mujoco>\n'
    )
    before = set(tmp_path.iterdir())
    assert run_cli([a.format(d=tmp_path) for a in args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err
    assert set(tmp_path.iterdir()) == before


def test_bad_input_exit_code_from_the_console(tmp_path):
    res = run("scene", "sdf", "nowhere", "--out", tmp_path / "x.png")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
