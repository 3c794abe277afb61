"""Robot-task prompts worded as a user would: does a model do the asked-for movement?

    python benchmarks/user_prompts.py --model controlmm/checkpoints/default --seeds 3
    python benchmarks/user_prompts.py --model MODEL_DIR --seeds 3 --json user_prompts.json

Three prompts per robot-task family (sit down, lie down, bow, pick up, kick, stretch the arms out,
push, look around, point, carry, step over, platform, stairs, and the sequences with a walk),
written by hand in words the corpus' caption templates never produce (checked against the corpus'
own captions when ``--corpus`` is there: a prompt found among them is an error). Each is generated
with ``generate(model, prompt, seconds=s, seed=k)`` (text only, both text views) for seeds
0..N-1 and checked with the family's probe (``controlmm.corpus.probes.probe``) and the claims its
words make. Prints the pass rate per family and overall. Beside ``controlmm eval probes`` on the
test split (held-out phrasings, but still the corpus' own vocabulary and sentence shapes), this is
how a new user's wording fares. Single-threaded (torch and BLAS) so that it can run beside other
work.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import torch  # noqa: E402
from data_dirs import DEFAULT_CORPUS  # noqa: E402

from controlmm.corpus.probes import probe  # noqa: E402
from controlmm.generate import generate, load_model  # noqa: E402

PROMPTS: tuple[tuple[str, str, dict, float], ...] = (
    # (family, prompt, claims its words make, seconds)
    ("sit_down", "someone lowers themselves into a chair", {}, 6.0),
    ("sit_down", "a man takes a seat for a moment and then gets back up", {"stand_up": True}, 7.0),
    ("sit_down", "a woman sits on a stool", {}, 6.0),
    ("lie_down", "someone lies flat on their back on the ground", {}, 7.0),
    ("lie_down", "a man lies down on the ground and then stands up again", {"stand_up": True}, 9.0),
    ("lie_down", "a woman gets down on the floor to lie on her back and rest", {}, 7.0),
    ("bow", "a man bows deeply to the crowd", {}, 4.0),
    ("bow", "someone bends forward from the hips in a bow", {}, 4.0),
    ("bow", "a performer takes a deep bow two times", {"count": 2}, 6.0),
    ("pick_up", "a person bends down to pick something up off the floor", {}, 5.0),
    ("pick_up", "someone squats to lift a box off the ground", {"style": "squat"}, 5.0),
    ("pick_up", "a woman reaches down to the ground and grabs an object", {}, 5.0),
    ("kick", "a person kicks a ball with the right foot", {"leg": "right"}, 4.0),
    ("kick", "someone does a front kick with their left leg", {"leg": "left", "kick": "front"}, 4.0),
    ("kick", "a man does a side kick using the right leg", {"leg": "right", "kick": "side"}, 4.0),
    ("stretch_arms", "a person holds their arms straight out in a t-pose", {}, 5.0),
    ("stretch_arms", "someone spreads both arms out horizontally", {}, 5.0),
    ("stretch_arms", "a man stretches his arms out sideways at shoulder level", {}, 5.0),
    ("push", "a person pushes against a wall with both hands", {}, 4.0),
    ("push", "someone shoves a heavy door open with both hands", {}, 4.0),
    ("push", "a man pushes a big crate away from himself", {}, 4.0),
    ("look_around", "someone turns their head to look around the room", {"look": "both"}, 5.0),
    ("look_around", "a man looks over to his left", {"look": "left"}, 4.0),
    ("look_around", "a woman checks over her right shoulder", {"look": "right"}, 4.0),
    ("point", "a person points at something in front of them with the right hand", {"hand": "right"}, 4.0),
    ("point", "someone points to their left with the left arm", {"hand": "left", "where": "left"}, 4.0),
    ("point", "a man lifts his right arm and points to the right", {"hand": "right", "where": "right"}, 4.0),
    ("carry", "a person walks forward holding a box in front of them", {}, 6.0),
    ("carry", "someone carries a heavy package while walking", {}, 6.0),
    ("carry", "a man walks ahead with a crate in his arms", {}, 6.0),
    ("step_over", "someone walks forward and steps across a low barrier", {}, 5.0),
    ("step_over", "a man walks along and lifts his feet over a log", {}, 5.0),
    ("step_over", "a person walks forward, stepping over something on the ground", {}, 5.0),
    ("platform", "a person steps up on top of a low platform", {"vertical": "up"}, 4.0),
    ("platform", "someone steps down off a ledge", {"vertical": "down"}, 4.0),
    ("platform", "a woman steps onto a higher surface in front of her", {"vertical": "up"}, 4.0),
    ("stairs", "someone walks upstairs", {"vertical": "up"}, 6.0),
    ("stairs", "a man heads downstairs", {"vertical": "down"}, 6.0),
    ("stairs", "a person ascends the stairs slowly", {"vertical": "up"}, 6.0),
    ("walk_then_sit", "a person walks to a chair, turns around and sits down", {}, 8.0),
    ("walk_then_sit", "someone walks across the room and sits down on a bench", {}, 8.0),
    ("walk_then_sit", "a man goes over to a stool and sits on it", {}, 8.0),
    ("walk_then_kick", "a person walks forward and then kicks with the right leg", {"leg": "right"}, 6.0),
    ("walk_then_kick", "someone walks up and kicks a ball with their left foot", {"leg": "left"}, 6.0),
    (
        "walk_then_kick",
        "a man steps up and kicks forward with his right foot",
        {"leg": "right", "kick": "front"},
        6.0,
    ),
    ("walk_then_bow", "a person walks forward and then bows", {}, 6.0),
    ("walk_then_bow", "someone walks up to the stage and takes a bow", {}, 6.0),
    ("walk_then_bow", "a man comes forward, stops and bows to the audience", {}, 6.0),
    ("pick_up_and_carry", "a person picks up a box and walks away with it", {}, 7.0),
    ("pick_up_and_carry", "someone lifts an object off the floor and carries it forward", {}, 7.0),
    ("pick_up_and_carry", "a woman grabs a bag from the ground and walks off holding it", {}, 7.0),
)
"""The prompts: three per robot-task family."""


def _normal(text: str) -> str:
    return " ".join(text.lower().strip().rstrip(".").split())


def corpus_captions(corpus: Path) -> set[str]:
    """Every caption of a corpus (``texts/*.txt``, normalised), or an empty set without one."""
    texts = corpus / "texts"
    if not texts.is_dir():
        return set()
    return {_normal(line.split("#")[0]) for f in texts.glob("*.txt") for line in f.read_text().splitlines()}


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", required=True, help="model directory ('default': the embedded model)")
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 per prompt (default 3)")
    parser.add_argument("--corpus", default=str(DEFAULT_CORPUS), help="corpus whose captions must differ")
    parser.add_argument("--json", default=None, help="also write every result to this JSON file")
    args = parser.parse_args()
    torch.set_num_threads(1)
    known = corpus_captions(Path(args.corpus))
    copied = [p for _, p, _, _ in PROMPTS if _normal(p) in known]
    if copied:
        sys.exit(f"prompts found among the corpus' captions: {copied}")
    model = load_model(None if args.model == "default" else args.model, skip=("control",))
    texts = [p for _, p, _, _ in PROMPTS]
    seconds = [s for _, _, _, s in PROMPTS]
    t0 = time.perf_counter()
    rows = []
    for seed in range(args.seeds):
        result = generate(model, texts, seconds=seconds, seed=seed)
        for (family, prompt, claims, _), motion in zip(PROMPTS, result.motions, strict=True):
            check = probe(motion, family, claims)
            rows.append(
                {
                    "family": family,
                    "prompt": prompt,
                    "seed": seed,
                    "passed": check.passed,
                    "failed": [f.name for f in check.failures()],
                }
            )
    wall = time.perf_counter() - t0
    print(
        f"model {model.directory}, {len(PROMPTS)} prompts x seeds 0-{args.seeds - 1}, {wall:.0f} s, "
        f"{'checked against ' + str(len(known)) + ' corpus captions' if known else 'no corpus to check'}"
    )
    print("\n| family | passed | rate | failed checks |\n|---|---|---|---|")
    families = list(dict.fromkeys(f for f, _, _, _ in PROMPTS))
    for family in families:
        sel = [r for r in rows if r["family"] == family]
        ok = sum(r["passed"] for r in sel)
        names = sorted({n for r in sel for n in r["failed"]})
        print(f"| {family} | {ok} / {len(sel)} | {100 * ok / len(sel):.0f} % | {', '.join(names) or '-'} |")
    ok = sum(r["passed"] for r in rows)
    print(f"| **all** | **{ok} / {len(rows)}** | **{100 * ok / len(rows):.1f} %** | |")
    if args.json:
        Path(args.json).write_text(json.dumps({"model": str(model.directory), "rows": rows}, indent=1) + "\n")
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
