import json
import os
import shutil
import subprocess
import sys
import textwrap

import pytest

from controlmm.atomic import (
    OUTPUT_MARKER,
    atomic_dir,
    atomic_open,
    atomic_path,
    check_output_dir,
    check_output_file,
    open_growing_dir,
    sweep_stale_temps,
    write_text,
)
from controlmm.errors import ControlMMError


def test_failed_write_leaves_nothing(tmp_path):
    target = tmp_path / "out.txt"
    with pytest.raises(RuntimeError):
        with atomic_open(target) as fh:
            fh.write("half")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_existing_file_survives_failed_rewrite(tmp_path):
    target = tmp_path / "out.txt"
    write_text(target, "old")
    with pytest.raises(RuntimeError):
        with atomic_open(target) as fh:
            fh.write("new")
            raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_atomic_dir_replaces_only_on_success(tmp_path):
    out = tmp_path / "run"
    with atomic_dir(out, kind="plan") as d:
        (d / "a.txt").write_text("1")
    with pytest.raises(RuntimeError):
        with atomic_dir(out, kind="plan") as d:
            (d / "b.txt").write_text("2")
            raise RuntimeError("boom")
    assert sorted(p.name for p in out.iterdir()) == [OUTPUT_MARKER, "a.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    with atomic_dir(out, kind="plan") as d:  # a previous output of the same kind is replaced
        (d / "c.txt").write_text("3")
    assert sorted(p.name for p in out.iterdir()) == [OUTPUT_MARKER, "c.txt"]


def test_missing_directories_are_made_and_a_file_in_the_way_is_one_line_error(tmp_path):
    write_text(tmp_path / "out" / "deeper" / "x.txt", "x")  # `--out out/walk` in a fresh folder
    assert (tmp_path / "out" / "deeper" / "x.txt").read_text() == "x"
    (tmp_path / "file").write_text("mine")
    with pytest.raises(ControlMMError, match="is not a directory"):
        write_text(tmp_path / "file" / "x.txt", "x")
    assert (tmp_path / "file").read_text() == "mine"


def test_a_users_directory_is_never_replaced_without_force(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("years of work")
    with pytest.raises(ControlMMError, match=r"not empty .* --force"):
        check_output_dir(out, kind="plan")
    with pytest.raises(ControlMMError, match="--force"):
        with atomic_dir(out, kind="plan") as d:
            (d / "report.json").write_text("{}")
    assert (out / "thesis.tex").read_text() == "years of work"
    with atomic_dir(out, kind="plan", force=True) as d:
        (d / "report.json").write_text("{}")
    assert sorted(p.name for p in out.iterdir()) == [OUTPUT_MARKER, "report.json"]


def test_a_previous_output_with_a_users_file_added_needs_force(tmp_path):
    out = tmp_path / "plan"
    with atomic_dir(out, kind="plan") as d:
        (d / "report.json").write_text("{}")
    (out / "notes.txt").write_text("mine")
    with pytest.raises(ControlMMError, match="--force"):
        check_output_dir(out, kind="plan")
    with pytest.raises(ControlMMError, match="--force"):  # another command's output
        (out / "notes.txt").unlink()
        check_output_dir(out, kind="corpus")
    check_output_dir(out, kind="plan")
    check_output_dir(tmp_path / "empty", kind="plan")


def test_a_growing_output_keeps_its_entries_and_is_resumed_without_force(tmp_path):
    out = tmp_path / "batch"
    assert open_growing_dir(out, kind="batch", make_parents=True) == out
    assert json.loads((out / OUTPUT_MARKER).read_text()) == {"kind": "batch", "files": None}
    with atomic_dir(out / "jobs" / "a", kind=None, make_parents=True) as d:  # entries added one by one
        (d / "result.json").write_text("{}")
    write_text(out / "summary.csv", "id\n")
    check_output_dir(out, kind="batch")  # any entry of a growing output is the command's
    open_growing_dir(out, kind="batch")  # resumed as it is
    assert (out / "jobs" / "a" / "result.json").is_file()
    with pytest.raises(ControlMMError, match=r"does not hold a previous 'plan' output"):
        check_output_dir(out, kind="plan")
    open_growing_dir(out, kind="batch", force=True)  # force: start over
    assert [p.name for p in out.iterdir()] == [OUTPUT_MARKER]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["batch"]


def test_a_growing_output_never_takes_over_a_users_directory(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("years of work")
    with pytest.raises(ControlMMError, match=r"not empty .* --force"):
        open_growing_dir(out, kind="batch")
    assert [p.name for p in out.iterdir()] == ["thesis.tex"]
    open_growing_dir(out, kind="batch", force=True)
    assert [p.name for p in out.iterdir()] == [OUTPUT_MARKER]
    (out / OUTPUT_MARKER).write_text(json.dumps({"kind": "batch", "files": ["x"]}))
    (out / "y").write_text("")  # a listed (not growing) output with an entry added needs force
    with pytest.raises(ControlMMError, match="--force"):
        check_output_dir(out, kind="batch")


def test_a_regular_file_is_never_replaced_by_a_directory(tmp_path):
    out = tmp_path / "data.csv"
    out.write_text("1,2,3")
    for force in (False, True):
        with pytest.raises(ControlMMError, match="is a file, not a directory"):
            with atomic_dir(out, kind="plan", force=force):
                pass
    assert out.read_text() == "1,2,3"
    assert [p.name for p in tmp_path.iterdir()] == ["data.csv"]


def test_existing_output_files_need_force(tmp_path):
    out = tmp_path / "walk.npz"
    check_output_file(out)
    out.write_text("mine")
    with pytest.raises(ControlMMError, match=r"'.*walk.npz' exists; pass --force"):
        check_output_file(out)
    check_output_file(out, force=True)
    with pytest.raises(ControlMMError, match="is a directory"):
        check_output_file(tmp_path)
    assert check_output_file(tmp_path / "no" / "x.npz") == tmp_path / "no" / "x.npz"
    assert not (tmp_path / "no").exists()  # checked, not made: nothing written before the work


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_read_only_directory_is_refused_before_work(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(ControlMMError, match="not writable"):
            check_output_dir(ro / "plan", kind="plan")
    finally:
        ro.chmod(0o700)


def _killed_writer(tmp_path, body: str) -> None:
    """Run ``body`` in a child process that SIGKILLs itself in the middle of an atomic write."""
    header = (
        "import os, signal\nfrom pathlib import Path\nfrom controlmm.atomic import atomic_dir, atomic_path\n"
    )
    code = header + f"out = Path({str(tmp_path)!r})\n" + body
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True)
    assert proc.returncode == -9, proc.stderr.decode()


def test_temporaries_of_a_killed_run_are_swept(tmp_path):
    body = """
with atomic_dir(out / "plan", kind="plan") as d:
    (d / "motion.npz").write_bytes(b"x" * 1000)
    os.kill(os.getpid(), signal.SIGKILL)
"""
    _killed_writer(tmp_path, body)
    body = """
with atomic_path(out / "walk.npz") as tmp:
    tmp.write_bytes(b"x")
    os.kill(os.getpid(), signal.SIGKILL)
"""
    _killed_writer(tmp_path, body)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert len(left) == 2 and all(name.endswith((".tmp", ".tmp.npz")) for name in left), left
    with atomic_dir(tmp_path / "plan", kind="plan") as d:
        (d / "report.json").write_text("{}")
    write_text(tmp_path / "walk.npz", "x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan", "walk.npz"]


def test_a_live_writers_temporaries_are_kept(tmp_path):
    with atomic_path(tmp_path / "a.txt") as tmp:
        tmp.write_text("in progress")
        assert sweep_stale_temps(tmp_path / "a.txt") == []  # our own process is alive
        assert tmp.exists()


@pytest.mark.skipif(shutil.which("unshare") is None, reason="needs unshare (util-linux) for a tiny tmpfs")
def test_a_full_disk_is_one_line_naming_the_users_path(tmp_path):
    """Write 2 MB into a 256 KiB tmpfs (a private mount namespace): one line, nothing left behind."""
    probe = subprocess.run(["unshare", "-rm", "true"], capture_output=True)
    if probe.returncode != 0:
        pytest.skip(f"user namespaces unavailable here: {probe.stderr.decode().strip()[:80]}")
    mnt = tmp_path / "small"
    mnt.mkdir()
    code = textwrap.dedent(
        f"""
        import sys
        from controlmm.atomic import atomic_dir, atomic_path
        from controlmm.errors import ControlMMError
        try:
            with atomic_path({str(mnt / "big.bin")!r}) as tmp:
                tmp.write_bytes(b"x" * 2_000_000)
        except ControlMMError as exc:
            print("file:", exc)
        try:
            with atomic_dir({str(mnt / "plan")!r}, kind="plan") as d:
                (d / "motion.npz").write_bytes(b"x" * 2_000_000)
        except ControlMMError as exc:
            print("dir:", exc)
        import os
        print("left:", sorted(os.listdir({str(mnt)!r})))
        """
    )
    (tmp_path / "writer.py").write_text(code)
    script = f"mount -t tmpfs -o size=256k tmpfs '{mnt}' && '{sys.executable}' '{tmp_path / 'writer.py'}'"
    proc = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert lines[0].startswith(f"file: no space left for '{mnt / 'big.bin'}'"), lines
    assert lines[1].startswith(f"dir: no space left for '{mnt / 'plan'}'"), lines
    assert lines[2] == "left: []"
    assert ".tmp" not in proc.stdout
