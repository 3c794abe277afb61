"""``controlmm train control``: masked consistency training of the motion control model."""

from __future__ import annotations

import argparse

from controlmm.cli.train import EPILOG, add_common_arguments, run_stage

# The choices of controlmm.training.control (tests check they agree), spelt out here so that building
# the parser (every `controlmm --help`) does not import torch.
ESTIMATORS = ("gumbel", "softmax")
CONTROL_MODES = ("trajectory", "random", "cross", "mixed")
DENSITIES = ("uniform", "mixed")

DESCRIPTION = """Train ControlMM's motion control model on MODEL_DIR's frozen tokenizer and masked transformer
(masked consistency training): a trainable copy of the transformer joined to the frozen base by
zero-initialised linear layers, fed the control signal (relative and absolute target positions of the
controlled joints). Each step masks the tokens, samples a control mask, predicts tokens, turns them
into codebook embeddings (straight-through Gumbel-softmax), decodes them with the frozen decoder,
recovers the global joints and adds the error on the controlled joints to the token cross-entropy:
loss = alpha CE + (1 - alpha) L1(controlled joints). Validation each epoch: the loss, token accuracy
and the joint error of the argmax tokens at the controlled entries (val_hard_err_cm)."""

EPILOG_CONTROL = """joints: all = pelvis, left/right foot, head, left/right wrist (36 input channels, the
official all-joint model; any other joint is reached by inference-time editing); pelvis = pelvis
only (6). Defaults: alpha 0.1 (the paper), estimator gumbel, mode mixed, density mixed, text dropout 0.1."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "control",
        help="train the motion control model (spatial control)",
        description=DESCRIPTION,
        epilog=EPILOG_CONTROL + "\n" + EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_common_arguments(p, creates=False)
    p.add_argument(
        "--joints",
        default=None,
        choices=("all", "pelvis"),
        help="joints the control branch sees (default: all)",
    )
    p.add_argument("--alpha", type=float, default=None, help="weight of the cross-entropy (default 0.1)")
    p.add_argument(
        "--estimator",
        default=None,
        choices=ESTIMATORS,
        help="token estimate for the consistency loss: gumbel (straight-through Gumbel-softmax, "
        "the paper; default) or softmax (the released code)",
    )
    p.add_argument("--tau", type=float, default=None, help="Gumbel-softmax temperature (default 1)")
    p.add_argument(
        "--mode",
        default=None,
        choices=CONTROL_MODES,
        help="control sampling: trajectory (pelvis), random (one control joint), cross "
        "(random frame/joint pairs), mixed (one of them per sample; default)",
    )
    p.add_argument(
        "--density",
        default=None,
        choices=DENSITIES,
        help="controlled frames per sample: uniform (1..196, the released code) or mixed "
        "(half of the samples log-uniform: sparse keyframes as often as dense; default)",
    )
    p.add_argument("--cond-drop", type=float, default=None, help="text dropout probability (default 0.1)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    options = {
        "joints": args.joints,
        "alpha": args.alpha,
        "estimator": args.estimator,
        "tau": args.tau,
        "mode": args.mode,
        "density": args.density,
        "cond_drop": args.cond_drop,
    }
    return run_stage("control", args, {k: v for k, v in options.items() if v is not None})
