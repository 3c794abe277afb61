"""A user's files survive every command, and bad input exits 2 with one line naming the user's path.

Each case runs the real command line in-process (``controlmm.cli.main.main``) on real files; the
checks that must come before any computation run in well under a second, before a model loads.
"""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np
import pytest
import torch

from controlmm.motion.skeleton import FEATURE_DIM
from tests.cli_helpers import one_line_error, run_cli


def _tree(path):
    return sorted(str(p.relative_to(path)) for p in path.rglob("*"))


@pytest.fixture
def users_dir(tmp_path):
    """A directory of the user's own work."""
    d = tmp_path / "experiments"
    d.mkdir()
    (d / "notes.md").write_text("my notes")
    (d / "data").mkdir()
    (d / "data" / "take1.npy").write_bytes(b"\x93NUMPY precious")
    return d


@pytest.mark.parametrize(
    "command",
    [
        ["plan", "--no-render"],
        ["corpus", "--clips", "2"],
        ["import-official", "--momask", "nowhere"],
    ],
)
def test_a_non_empty_directory_is_refused(users_dir, capsys, command):
    before = _tree(users_dir)
    one_line_error(capsys, [*command, "--out", str(users_dir)], str(users_dir), "--force")
    assert _tree(users_dir) == before
    assert (users_dir / "notes.md").read_text() == "my notes"
    assert sorted(p.name for p in users_dir.parent.iterdir()) == ["experiments"]  # no temporaries


@pytest.mark.parametrize("command", [["plan", "--no-render"], ["corpus", "--clips", "2"]])
def test_a_regular_file_is_never_replaced_by_an_output_directory(tmp_path, capsys, command):
    target = tmp_path / "results.csv"
    target.write_text("1,2,3\n")
    for force in ([], ["--force"]):
        one_line_error(capsys, [*command, "--out", str(target), *force], str(target), "is a file")
    assert target.read_text() == "1,2,3\n"
    assert [p.name for p in tmp_path.iterdir()] == ["results.csv"]  # no hidden .old copy


def test_existing_output_files_need_force(tmp_path, capsys, sample_features):
    src = tmp_path / "in.npy"
    np.save(src, sample_features[:30])
    out = tmp_path / "out.npz"
    out.write_text("the user's file")
    for argv in (
        ["convert", str(src), str(out)],
        ["plot", str(src), "--out", str(out.with_suffix(".png"))],
        ["generate", "--text", "a person walks", "--out", str(out)],
        ["timeline", "spec.json", "--out", str(out)],
    ):
        out.with_suffix(".png").write_text("the user's picture")
        one_line_error(capsys, argv, "exists; pass --force")
    assert out.read_text() == "the user's file"
    assert run_cli(["convert", str(src), str(out), "--force"]) == 0
    assert np.load(out)["joints"].shape == (30, 22, 3)


def test_retarget_refuses_to_replace_any_of_its_three_files(tmp_path, capsys, sample_joints):
    src = tmp_path / "walk.npy"
    np.save(src, sample_joints[:20])
    (tmp_path / "g1.json").write_text("{}")
    one_line_error(capsys, ["retarget", str(src), "--out", str(tmp_path / "g1")], "g1.json' exists")
    assert (tmp_path / "g1.json").read_text() == "{}"
    assert not (tmp_path / "g1.csv").exists()


def test_a_previous_plan_output_is_replaced_but_a_users_addition_protects_it(tmp_path, capsys):
    from controlmm.atomic import atomic_dir

    out = tmp_path / "plan"
    with atomic_dir(out, kind="plan") as d:  # what a plan leaves (write_plan's marker)
        (d / "report.json").write_text("{}")
    # accepted: the bad --seed below is then the only error (after the output check)
    one_line_error(capsys, ["plan", "--out", str(out), "--seed", "-1", "--no-render"], "seed")
    (out / "my_notes.txt").write_text("mine")
    one_line_error(capsys, ["plan", "--out", str(out), "--no-render"], "--force")
    assert (out / "my_notes.txt").read_text() == "mine"


@pytest.mark.parametrize("command", ["generate", "plan", "timeline"])
def test_seeds_beyond_64_bits_are_one_line(tmp_path, capsys, command):
    argv = {
        "generate": ["generate", "--text", "a person walks"],
        "plan": ["plan", "--no-render"],
        "timeline": ["timeline", "spec.json"],
    }[command]
    out = tmp_path / ("p" if command == "plan" else "m.npz")
    for seed in (str(2**64 + 5), "-3"):
        one_line_error(capsys, [*argv, "--out", str(out), "--seed", seed], "seed", seed)
    assert not out.exists()


def test_one_frame_features_are_one_line(tmp_path, capsys):
    src = tmp_path / "one.npy"
    np.save(src, np.zeros((1, FEATURE_DIM), np.float32))
    for argv in (
        ["convert", str(src), str(tmp_path / "o.npz")],
        ["retarget", str(src), "--out", str(tmp_path / "r")],
        ["plot", str(src), "--out", str(tmp_path / "o.png")],
    ):
        one_line_error(capsys, argv, "at least 2 frames", str(src))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one.npy"]


def test_nan_names_the_file_and_frame(tmp_path, capsys, sample_joints):
    joints = sample_joints[:40].copy()
    joints[17, 3, 1] = np.nan
    src = tmp_path / "nan.npy"
    np.save(src, joints)
    one_line_error(capsys, ["convert", str(src), str(tmp_path / "o.npz")], str(src), "frame 17")


def test_a_directory_given_as_a_file_says_so(tmp_path, capsys):
    folder = tmp_path / "motion.npz"
    folder.mkdir()
    one_line_error(capsys, ["convert", str(folder), str(tmp_path / "o.npz")], "is a directory")
    one_line_error(
        capsys,
        ["validate", str(tmp_path / "motion.npz"), "--out", str(tmp_path / "r.json")],
        "is a directory",
    )


def test_renamed_text_files_are_not_valid_and_no_unsafe_advice(tmp_path, capsys):
    fake = tmp_path / "motion.npz"
    fake.write_text("just some text\n")
    err = one_line_error(capsys, ["convert", str(fake), str(tmp_path / "o.bvh")], "not a valid NPZ file")
    err += one_line_error(capsys, ["validate", str(fake), "--out", str(tmp_path / "r.json")], "not a valid")
    assert "allow_pickle" not in err and "pickle=True" not in err
    from controlmm.errors import InputFileError
    from controlmm.files import load_torch

    ckpt = tmp_path / "latest.tar"
    ckpt.write_text("not a checkpoint")
    with pytest.raises(InputFileError, match="not a valid checkpoint") as info:
        load_torch(ckpt)
    assert "weights_only" not in str(info.value)
    torch.save({"w": torch.zeros(2), "obj": np.random.default_rng(0)}, ckpt)  # pickled object: refused
    with pytest.raises(InputFileError, match="Python objects besides tensors"):
        load_torch(ckpt, hint="train it again with --force")


def test_retarget_rejects_joints_that_are_not_metres(tmp_path, capsys, sample_joints):
    for scale, needle in ((100.0, "centimetres"), (1e9, "size of a person in metres")):
        src = tmp_path / f"x{scale:g}.npy"
        np.save(src, sample_joints[:20] * scale)
        one_line_error(capsys, ["retarget", str(src), "--out", str(tmp_path / "r")], needle, str(src))
    assert not list(tmp_path.glob("r.*"))


def test_scene_show_lists_the_robots_retarget_and_plan_list(tmp_path, capsys, sample_joints):
    src = tmp_path / "walk.npy"
    np.save(src, sample_joints[:20])
    errors = [
        one_line_error(capsys, argv, "nao")
        for argv in (
            ["scene", "show", "table", "--robot", "nao", "--out", str(tmp_path / "s.png")],
            ["retarget", str(src), "--robot", "nao", "--out", str(tmp_path / "r")],
            ["plan", "--robot", "nao", "--out", str(tmp_path / "p"), "--no-render"],
        )
    ]
    known = {e.split("known robots:")[1] for e in errors}
    assert len(known) == 1, errors  # the same list everywhere
    assert [p.name for p in tmp_path.iterdir()] == ["walk.npy"]


def test_writability_is_checked_before_any_work(tmp_path, capsys):
    (tmp_path / "ro.txt").write_text("x")
    one_line_error(capsys, ["plan", "--out", str(tmp_path / "ro.txt" / "plan")], "ro.txt", "not a directory")


@pytest.mark.skipif(shutil.which("unshare") is None, reason="needs unshare (util-linux) for a tiny tmpfs")
def test_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, sample_features):
    """``controlmm convert`` into a 64 KiB tmpfs (a private mount namespace): exit 2, one line."""
    probe = subprocess.run(["unshare", "-rm", "true"], capture_output=True)
    if probe.returncode != 0:
        pytest.skip(f"user namespaces unavailable here: {probe.stderr.decode().strip()[:80]}")
    src = tmp_path / "in.npy"
    np.save(src, np.tile(sample_features, (4, 1)))
    mnt = tmp_path / "small"
    mnt.mkdir()
    script = (
        f"mount -t tmpfs -o size=64k tmpfs '{mnt}' && "
        f"'{sys.executable}' -m controlmm convert '{src}' '{mnt / 'big.npy'}' --joints; "
        f"echo rc=$?; ls -A '{mnt}'"
    )
    proc = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True)
    err = proc.stderr.strip()
    assert err.startswith(f"controlmm: error: no space left for '{mnt / 'big.npy'}'"), err
    assert err.endswith("nothing was written") and "\n" not in err and ".tmp" not in err, err
    assert proc.stdout.strip() == "rc=2"  # and `ls -A` printed nothing: no temporary left


def test_info_lists_the_robots_plan_accepts(capsys):
    from retarget import packaged_mappings

    assert run_cli(["info"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("robots"))
    assert line.split(None, 1)[1] == ", ".join(packaged_mappings())


def test_a_corrupt_training_checkpoint_says_how_to_start_over(tmp_path):
    from controlmm.errors import InputFileError
    from controlmm.training.checkpoint import load_checkpoint, rng_state, save_checkpoint, set_rng_state

    path = tmp_path / "checkpoints" / "tokenizer.pt"
    save_checkpoint(path, {"step": 3, "model": {"w": torch.ones(2)}, "rng": [rng_state()]})
    data = load_checkpoint(path)  # tensors and plain containers only: loads without unpickling code
    expected = np.random.rand()
    set_rng_state(data["rng"][0])
    assert np.random.rand() == expected  # the RNG state round-trips
    path.write_bytes(path.read_bytes()[:100])  # truncated by a full disk or a bad copy
    with pytest.raises(InputFileError, match=r"not a valid checkpoint .*start this stage over with --force"):
        load_checkpoint(path)
