"""Training: losses go down, checkpoints are complete and atomic, SIGKILL + --resume, DDP over gloo."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest
import torch
import torch.multiprocessing as mp

from controlmm.errors import ControlMMError, InputFileError
from controlmm.models.config import StageSchedule
from controlmm.training import TrainOptions, lr_factor, train

from .conftest import subprocess_env


def test_every_stage_lowers_its_validation_loss(tiny_model_dir):
    manifest = json.loads((tiny_model_dir / "model.json").read_text())
    assert set(manifest["parts"]) == {"tokenizer", "transformer", "residual"}
    for stage in ("tokenizer", "transformer", "residual"):
        ckpt = torch.load(tiny_model_dir / "checkpoints" / f"{stage}.pt", weights_only=False)
        history = ckpt["history"]
        key = "val_mpjpe_mm" if stage == "tokenizer" else "val_loss"
        assert history[-1][key] < history[0][key], stage
        record = manifest["training"][stage]
        assert record["iterations"] == ckpt["step"] and record["wall_time_s"] >= 0
        assert record["best"][key] == min(h[key] for h in history)
    # The transformers remember which tokenizer they were trained on.
    sha = manifest["parts"]["tokenizer"]["sha256"]
    assert manifest["parts"]["transformer"]["trained_on"] == {"tokenizer": sha}


def test_checkpoint_holds_everything_to_resume(tiny_model_dir):
    ckpt = torch.load(tiny_model_dir / "checkpoints" / "tokenizer.pt", weights_only=False)
    for key in ("model", "optimizer", "scheduler", "rng", "step", "history", "best_state", "extra"):
        assert key in ckpt
    assert ckpt["step"] == 30 and len(ckpt["optimizer"]["state"]) > 0
    assert ckpt["scheduler"]["last_epoch"] == 30 and set(ckpt["rng"][0]) >= {"python", "numpy", "torch"}
    assert "0.code_count" in ckpt["extra"]["ema"]
    assert not list((tiny_model_dir / "checkpoints").glob("*.tmp*"))


def test_learning_rate_schedule():
    s = StageSchedule(iters=100, batch_size=4, lr=1.0, warmup=9, milestones=(50, 80), gamma=0.1)
    assert lr_factor(0, s) == pytest.approx(0.1)
    assert lr_factor(9, s) == pytest.approx(1.0)
    assert lr_factor(50, s) == pytest.approx(0.1) and lr_factor(80, s) == pytest.approx(0.01)


def test_refuses_to_clobber_and_checks_prerequisites(tiny_data, tiny_model_dir, tmp_path):
    with pytest.raises(ControlMMError, match="--resume to continue it or --force"):
        train("tokenizer", TrainOptions(data=tiny_data, out=tiny_model_dir, iters=1, progress=False))
    with pytest.raises(InputFileError, match="train the tokenizer first"):
        train("transformer", TrainOptions(data=tiny_data, out=tmp_path / "fresh", progress=False))
    with pytest.raises(InputFileError, match="nothing to resume"):
        train("tokenizer", TrainOptions(data=tiny_data, out=tmp_path / "fresh", resume=True, progress=False))
    with pytest.raises(ControlMMError, match="unknown preset 'huge'"):
        train("tokenizer", TrainOptions(data=tiny_data, out=tmp_path / "x", preset="huge", progress=False))
    with pytest.raises(ControlMMError, match="--preset demo does not match"):
        train(
            "residual",
            TrainOptions(data=tiny_data, out=tiny_model_dir, preset="demo", resume=True, progress=False),
        )


def _cli_train(data, out, *extra):
    return [
        sys.executable,
        "-m",
        "controlmm",
        "train",
        "tokenizer",
        "--data",
        str(data),
        "--out",
        str(out),
        "--preset",
        "tiny",
        "--batch-size",
        "4",
        "--no-progress",
        "--device",
        "cpu",
        *extra,
    ]


def _weights(path):
    return torch.load(path, weights_only=True)["state_dict"]


def test_sigkill_then_resume_matches_an_uninterrupted_run(tiny_data, tmp_path):
    iters = "36"
    env = subprocess_env()
    straight = subprocess.run(
        _cli_train(tiny_data, tmp_path / "a", "--iters", iters, "--checkpoint-every", "3"),
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert straight.returncode == 0, straight.stderr
    ckpt = tmp_path / "b" / "checkpoints" / "tokenizer.pt"
    proc = subprocess.Popen(
        _cli_train(tiny_data, tmp_path / "b", "--iters", iters, "--checkpoint-every", "3"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    killed_at = None
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if ckpt.is_file():
            step = torch.load(ckpt, weights_only=False)["step"]  # always loadable: written atomically
            if step >= 9:
                os.kill(proc.pid, signal.SIGKILL)
                killed_at = step
                break
        time.sleep(0.05)
    proc.wait(timeout=30)
    assert killed_at is not None and proc.returncode == -signal.SIGKILL
    assert not (tmp_path / "b" / "tokenizer.pt").exists()
    saved = torch.load(ckpt, weights_only=False)["step"]
    assert saved < int(iters)
    resumed = subprocess.run(
        _cli_train(tiny_data, tmp_path / "b", "--iters", iters, "--checkpoint-every", "3", "--resume"),
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert resumed.returncode == 0, resumed.stderr
    assert f"resumed tokenizer from step {saved}" in resumed.stdout
    a, b = _weights(tmp_path / "a" / "tokenizer.pt"), _weights(tmp_path / "b" / "tokenizer.pt")
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _ddp_worker(rank: int, world: int, port: int, data: str, out: str, result_dir: str) -> None:
    os.environ.update(
        MASTER_ADDR="127.0.0.1",
        MASTER_PORT=str(port),
        RANK=str(rank),
        WORLD_SIZE=str(world),
        LOCAL_RANK=str(rank),
    )
    torch.set_num_threads(1)
    from pathlib import Path

    result = train(
        "tokenizer",
        TrainOptions(
            data=Path(data),
            out=Path(out),
            preset="tiny",
            iters=6,
            batch_size=4,
            checkpoint_every=2,
            progress=False,
            device="cpu",
        ),
    )
    torch.save(
        {k: v.clone() for k, v in result.model.state_dict().items()}, Path(result_dir) / f"rank{rank}.pt"
    )


def test_distributed_data_parallel_on_two_gloo_processes(tiny_data, tmp_path):
    context = mp.spawn(
        _ddp_worker,
        args=(2, _free_port(), str(tiny_data), str(tmp_path / "ddp"), str(tmp_path)),
        nprocs=2,
        join=False,
    )
    deadline = time.time() + 180
    while not context.join(timeout=1):
        if time.time() > deadline:  # a collective mismatch would hang forever: fail instead
            for process in context.processes:
                process.kill()
            pytest.fail("the two DDP processes did not finish within 180 s")
    r0, r1 = torch.load(tmp_path / "rank0.pt"), torch.load(tmp_path / "rank1.pt")
    for key in r0:  # gradients and codebook statistics are synchronised: identical replicas
        assert torch.allclose(r0[key], r1[key], atol=1e-6), key
    ckpt = torch.load(tmp_path / "ddp" / "checkpoints" / "tokenizer.pt", weights_only=False)
    assert ckpt["world"] == 2 and len(ckpt["rng"]) == 2 and ckpt["step"] == 6
    manifest = json.loads((tmp_path / "ddp" / "model.json").read_text())
    assert manifest["training"]["tokenizer"]["processes"] == 2
    initial = torch.load(tmp_path / "ddp" / "checkpoints" / "tokenizer.pt", weights_only=False)["history"]
    assert len(initial) >= 1


def test_clip_conditioned_model_trains_and_generates(tiny_data, tiny_clip_dir, tmp_path):
    from controlmm.generate import generate, load_model

    out = tmp_path / "clip-model"
    train(
        "tokenizer",
        TrainOptions(
            data=tiny_data,
            out=out,
            preset="tiny",
            iters=4,
            progress=False,
            text_encoder="clip",
            clip_weights=str(tiny_clip_dir),
        ),
    )
    manifest = json.loads((out / "model.json").read_text())
    assert manifest["text_encoder"]["name"] == "clip" and manifest["config"]["transformer"]["text_dim"] == 24
    train("transformer", TrainOptions(data=tiny_data, out=out, iters=3, progress=False))
    assert len(list((out / "cache").glob("text-clip-*.pt"))) == 1
    model = load_model(out)
    result = generate(model, "a person squats slowly", frames=48, seed=0)
    assert result.motion.joints.shape == (48, 22, 3) and model.residual is None


def test_text_token_model_trains_every_stage_and_generates(tiny_data, tmp_path):
    from controlmm.generate import generate, load_model

    out = tmp_path / "token-model"
    train(
        "tokenizer",
        TrainOptions(data=tiny_data, out=out, preset="tiny", iters=4, progress=False, text_tokens=12),
    )
    assert json.loads((out / "model.json").read_text())["config"]["text_encoder"]["tokens"] == 12
    with pytest.raises(ControlMMError, match="uses text tokens 12; --text-tokens 0 does not match"):
        train("transformer", TrainOptions(data=tiny_data, out=out, iters=2, progress=False, text_tokens=0))
    for stage in ("transformer", "residual", "control"):
        train(stage, TrainOptions(data=tiny_data, out=out, iters=2, progress=False))
    assert len(list((out / "cache").glob("text-minilm-tok12-*.pt"))) == 1
    model = load_model(out)
    cond = model.encode_text(["a person squats slowly", "a person walks forward and then turns around"])
    assert cond.ndim == 3 and cond.shape[0] == 2 and cond.shape[1] <= 12
    result = generate(model, ["a person squats slowly", "someone jumps"], frames=[48, 40], seed=0)
    assert [m.joints.shape for m in result.motions] == [(48, 22, 3), (40, 22, 3)]
    # Control model, logits and codebook editing on the token states (loose target: 2 training steps).
    from controlmm.control import ControlSpec
    from controlmm.generate import generate_controlled

    target = result.motions[0].joints[20, 0].tolist()
    spec = ControlSpec.from_dict(
        {"coords": "human", "constraints": [{"joint": "pelvis", "frame": 20, "position": target}]}
    )
    out = generate_controlled(model, "a person squats slowly", control=spec, frames=48, preset="fast", seed=1)
    assert out.motion.joints.shape == (48, 22, 3) and out.records[0].control_model
    assert float(out.errors[0].max()) < 0.05


def test_validation_draws_do_not_depend_on_the_training_seed(tiny_data, tiny_model_dir):
    # Runs with different --seed are validated on the same crops, captions and masks, so their
    # validation losses (and which checkpoint each exports) are comparable.
    from controlmm.data.humanml3d import HumanML3D
    from controlmm.generate import load_model
    from controlmm.training.model_stage import StageContext
    from controlmm.training.residual import ResidualStage
    from controlmm.training.transformer import TransformerStage

    model = load_model(tiny_model_dir)
    metrics = {}
    for seed in (0, 5):
        ctx = StageContext(
            config=model.config,
            data=HumanML3D(tiny_data),
            normalizer=model.normalizer,
            model_dir=tiny_model_dir,
            device=torch.device("cpu"),
            seed=seed,
            progress=False,
            base=load_model(tiny_model_dir, parts=("tokenizer",)),
        )
        torch.manual_seed(seed)  # the global generator must not matter either
        metrics[seed] = (
            TransformerStage(ctx).validate(model.transformer),
            ResidualStage(ctx).validate(model.residual),
        )
    assert metrics[0] == metrics[5]
    assert metrics[0][0]["val_loss"] > 0 and metrics[0][1]["val_loss"] > 0
