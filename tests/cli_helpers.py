"""Running the ``controlmm`` command line in-process, as the console script does, or in a subprocess."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys

from controlmm.cli.main import main


def run_cli(argv: list[str]) -> int:
    """The exit status of ``controlmm ARGV``: main's return value, or argparse's exit code for
    ``--help`` (0) and bad argument values (2, one line on stderr)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else 1


def in_process(*args: object) -> subprocess.CompletedProcess:
    """``controlmm ARGS`` run in this process (:func:`run_cli`), its exit status and output
    captured like :func:`console`'s, without a new interpreter's seconds of imports."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = run_cli([str(a) for a in args])
    return subprocess.CompletedProcess(["controlmm", *map(str, args)], code, out.getvalue(), err.getvalue())


def one_line_error(capsys, argv: list[str], *needles: str) -> str:
    """Assert ``controlmm ARGV`` exits 2 with one stderr line holding every needle; return it."""
    code = run_cli(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    return err.strip()


def console(*args: object, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """``python -m controlmm ARGS`` in a subprocess (its own environment ``env``, e.g. MUJOCO_GL),
    output captured as text."""
    return subprocess.run(
        [sys.executable, "-m", "controlmm", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
