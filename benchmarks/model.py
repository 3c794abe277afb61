"""Benchmark of the masked motion model: generation latency and training throughput per stage.

    python benchmarks/model.py                      # demo preset, random weights, 2 threads
    python benchmarks/model.py --model MODEL_DIR    # latency of a trained model directory
    python benchmarks/model.py --data DIR           # training throughput on a real dataset/corpus

Latency: one 196-frame generation (text encoding, 10 masked-decoding iterations with CFG, 5 residual
layers with CFG, RVQ-VAE decoding, recovery of the joints), base model without control; median and
best of ``--repeats`` runs after one warm-up. Throughput: the real training loop (``controlmm.training``)
for ``--iters`` iterations per stage with the preset's batch size, validation excluded. Without --data
the data is a HumanML3D-format directory built from the real sample motion 012314 (crops, mirror, time
stretch), which is enough for timing (not for quality).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from data_dirs import humanml3d_dir, real_clip

PROMPT = "a person walks forward, turns around and walks back"


def synthetic_dataset(root: Path, clips: int = 200) -> Path:
    """A HumanML3D-format directory of ``clips`` motions cut from the real sample (timing only)."""
    from controlmm.motion import joints_to_features
    from controlmm.motion.container import resample
    from controlmm.motion.skeleton import LEFT_RIGHT_MIRROR

    feats = np.load(real_clip("new_joint_vecs"))
    joints = np.load(real_clip("new_joints"))
    mirrored = joints.copy()
    mirrored[..., 0] *= -1
    sources = [feats, joints_to_features(mirrored[:, list(LEFT_RIGHT_MIRROR)])[0]]
    for speed in (0.85, 1.15):
        sources.append(joints_to_features(resample(joints, 20.0 * speed, 20.0))[0])
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    rng = np.random.default_rng(0)
    words = ["walks", "bends", "turns", "squats", "waves", "jumps", "runs", "crouches"]
    ids = []
    for k in range(clips):
        src = sources[k % len(sources)]
        length = int(rng.integers(60, min(len(src), 196)))
        start = int(rng.integers(0, len(src) - length + 1))
        motion_id = f"{k:06d}"
        np.save(root / "new_joint_vecs" / f"{motion_id}.npy", src[start : start + length].astype(np.float32))
        lines = [f"a person {words[(k + j) % 8]} slowly#a/DET person/NOUN#0.0#0.0" for j in range(3)]
        (root / "texts" / f"{motion_id}.txt").write_text("\n".join(lines) + "\n")
        ids.append(motion_id)
    n_val = max(8, clips // 20)
    (root / "train.txt").write_text("\n".join(ids[n_val:]) + "\n")
    (root / "val.txt").write_text("\n".join(ids[:n_val]) + "\n")
    (root / "test.txt").write_text("\n".join(ids[:n_val]) + "\n")
    shutil.copy(humanml3d_dir() / "Mean.npy", root / "Mean.npy")
    shutil.copy(humanml3d_dir() / "Std.npy", root / "Std.npy")
    return root


def random_model(preset: str):
    """A MotionModel of ``preset`` with freshly initialised weights (latency does not depend on them)."""
    from controlmm.models import preset_config
    from controlmm.models.model_dir import PARTS, MotionModel, new_manifest
    from controlmm.motion.normalization import Normalizer

    cfg = preset_config(preset)
    names = ("tokenizer", "transformer", "residual") + (("token_transformer",) if cfg.token_view else ())
    parts = {name: PARTS[name].build(cfg).eval().requires_grad_(False) for name in names}
    normalizer = Normalizer.load(humanml3d_dir() / "Mean.npy", humanml3d_dir() / "Std.npy").with_feat_bias()
    return MotionModel(config=cfg, normalizer=normalizer, parts=parts, manifest=new_manifest(cfg, {}))


def time_generation(model, repeats: int) -> dict[str, float]:
    from controlmm.generate import DecodeOptions, masked_decode, residual_decode, token_view_logits_fn
    from controlmm.generate.api import generate, latent_to_features
    from controlmm.motion.recover import features_to_joints

    generate(model, PROMPT, frames=196, seed=0)  # warm-up (loads the text encoder)
    totals, cpu, parts = [], [], {"text": [], "base": [], "residual": [], "decode": []}
    for r in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        generate(model, PROMPT, frames=196, seed=r)
        totals.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        with torch.no_grad():
            t = time.perf_counter()
            cond, states = model.encode_text_views([PROMPT])  # one MiniLM pass for both views
            views = token_view_logits_fn(model, [PROMPT], DecodeOptions().cfg_scale, states)
            parts["text"].append(time.perf_counter() - t)
            lengths = torch.tensor([49])
            gen = torch.Generator().manual_seed(r)
            t = time.perf_counter()
            base = masked_decode(model.transformer, cond, lengths, DecodeOptions(), gen, logits_fn=views)
            parts["base"].append(time.perf_counter() - t)
            t = time.perf_counter()
            ids, _ = residual_decode(model.residual, base.ids, cond, lengths, generator=gen)
            parts["residual"].append(time.perf_counter() - t)
            t = time.perf_counter()
            features_to_joints(latent_to_features(model, model.tokenizer.ids_to_latent(ids)))
            parts["decode"].append(time.perf_counter() - t)
    out = {"median": statistics.median(totals), "best": min(totals), "cpu": statistics.median(cpu)}
    out.update({k: statistics.median(v) for k, v in parts.items()})
    return out


def time_training(data: Path, preset: str, iters: int, workdir: Path, precision: str) -> dict[str, dict]:
    from controlmm.models import preset_config
    from controlmm.training import TrainOptions, train

    out = workdir / f"model-{precision}"
    results = {}
    stages = (
        ("tokenizer", "transformer")
        + (("token_transformer",) if preset_config(preset).token_view else ())
        + ("residual",)
    )
    for stage in stages:
        train(
            stage,
            TrainOptions(
                data=data,
                out=out,
                preset=preset,
                iters=iters,
                progress=False,
                device="cpu",
                checkpoint_every=10**9,
                precision=precision,
                threads=torch.get_num_threads(),
            ),
        )
        record = json.loads((out / "model.json").read_text())["training"][stage]
        results[stage] = record
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--preset", default="demo")
    parser.add_argument("--model", default=None, help="trained model directory for the latency figure")
    parser.add_argument("--data", default=None, help="HumanML3D-format directory for the throughput figures")
    parser.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--iters", type=int, default=20, help="training iterations timed per stage")
    parser.add_argument(
        "--precision", default="fp32,bf16", help="training precisions to time (default fp32,bf16)"
    )
    parser.add_argument("--skip-training", action="store_true")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    from controlmm.generate import load_model
    from controlmm.models import preset_config

    model = load_model(args.model) if args.model else random_model(args.preset)
    complete = "transformer" in model.parts and "residual" in model.parts
    lat = time_generation(model, args.repeats) if complete else {}
    rows = [
        (
            "machine",
            f"{platform.machine()}, {os.cpu_count()} CPU cores, torch {torch.__version__}, "
            f"{args.threads} threads, load average {os.getloadavg()[0]:.1f}",
        ),
        ("model", f"{args.model or 'random ' + args.preset + ' weights'}"),
    ]
    if lat:
        views = ", both text views" if model.token_transformer is not None else ""
        rows += [
            ("generation 196 frames, wall (median / best)", f"{lat['median']:.3f} s / {lat['best']:.3f} s"),
            ("generation 196 frames, CPU time (median)", f"{lat['cpu']:.3f} s"),
            ("  text encoding (MiniLM)", f"{lat['text'] * 1000:.0f} ms"),
            ("  base layer, 10 iterations, CFG 4" + views, f"{lat['base'] * 1000:.0f} ms"),
            ("  residual layers 1-5, CFG 5", f"{lat['residual'] * 1000:.0f} ms"),
            ("  RVQ-VAE decoding + joints", f"{lat['decode'] * 1000:.0f} ms"),
        ]
    if args.model and args.data:
        from controlmm.data import HumanML3D
        from controlmm.training.tokenizer import reconstruction_metrics

        rec = reconstruction_metrics(model, HumanML3D(args.data), "test")
        rows.append(
            (
                f"tokenizer reconstruction, test split ({rec['motions']} motions)",
                f"MPJPE {rec.get('mpjpe_mm', float('nan')):.1f} mm (pelvis-aligned, MoMask), "
                f"global {rec.get('global_mpjpe_mm', float('nan')):.1f} mm",
            )
        )
    if not args.skip_training:
        cfg = preset_config(args.preset)
        with tempfile.TemporaryDirectory() as tmp:
            data = Path(args.data) if args.data else synthetic_dataset(Path(tmp) / "data")
            for precision in args.precision.split(","):
                records = time_training(data, args.preset, args.iters, Path(tmp), precision)
                total_wall = total_cpu = 0.0
                for stage, rec in records.items():
                    schedule = cfg.schedules[stage]
                    rate, cpu_s = rec["throughput_it_s"], rec["cpu_s_per_it"]
                    wall_min = schedule.iters / rate / 60 if rate else float("nan")
                    total_wall += wall_min
                    total_cpu += schedule.iters * cpu_s / 60
                    rows.append(
                        (
                            f"train {stage} ({precision}, batch {rec['schedule']['batch_size']})",
                            f"{rate:.2f} it/s wall, {cpu_s:.2f} CPU-s/it; plan {schedule.iters} it = "
                            f"{wall_min:.0f} min at this rate",
                        )
                    )
                rows.append(
                    (
                        f"planned training, {len(records)} stages ({precision})",
                        f"{total_wall:.0f} min wall at these rates, {total_cpu:.0f} CPU-min "
                        "(without validation)",
                    )
                )
    width = max(len(k) for k, _ in rows)
    print(f"| {'measurement':<{width}} | value |")
    print(f"|{'-' * (width + 2)}|-------|")
    for key, value in rows:
        print(f"| {key:<{width}} | {value} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
