"""Captions: POS tokens, variety, held-out phrasings and claims that match the parameters."""

from __future__ import annotations

import numpy as np
import pytest

from controlmm.corpus import family_names, get_family
from controlmm.corpus.text.pos import LEXICON, tag
from controlmm.corpus.text.templates import phrase_words
from controlmm.errors import ControlMMError


def test_tagger_writes_humanml3d_tokens():
    assert tag("A person walks forward.") == "a/DET person/NOUN walk/VERB forward/ADV"
    assert tag("someone waves their left hand.") == "someone/PRON wave/VERB their/DET left/ADJ hand/NOUN"
    assert tag("a man turns to the right.") == "a/DET man/NOUN turn/VERB to/ADP the/DET right/NOUN"
    assert tag("a woman does two jumps.") == "a/DET woman/NOUN do/VERB two/NUM jump/NOUN"
    assert tag("a woman jumps 3 times.") == "a/DET woman/NOUN jump/VERB 3/NUM time/NOUN"
    with pytest.raises(ControlMMError, match="xylophone"):
        tag("a person walks with a xylophone")


def test_every_word_a_family_can_write_is_in_the_lexicon():
    for name in family_names():
        family = get_family(name)
        for seed in range(12):
            params = family.sample(np.random.default_rng(seed))
            words = phrase_words(family.templates, family.slots(params))
            unknown = {
                w for w in words if w not in LEXICON and not w.isdigit() and w not in ("left", "right")
            }
            assert not unknown, (name, unknown)


def test_captions_are_varied_true_to_parameters_and_hold_out_phrasings():
    for name in family_names():
        family = get_family(name)
        assert sum(t.held for t in family.templates) >= 1 and sum(not t.held for t in family.templates) >= 3
        rng = np.random.default_rng(hash(name) % 2**32)
        params = family.sample(rng)
        train = family.captions(params, rng, held_out=False, count=3)
        test = family.captions(params, rng, held_out=True, count=3)
        assert len({c.text for c in train}) == 3 and len({c.text for c in test}) == 3
        assert not any(c.held_out for c in train) and all(c.held_out for c in test)
        for cap in train + test:
            for key in ("hand", "knee", "count", "angle"):
                if key in cap.claims and key in params:
                    assert cap.claims[key] == params[key], (name, cap.text)
            if "hand" in cap.claims and cap.claims["hand"] in ("left", "right"):
                other = "right" if cap.claims["hand"] == "left" else "left"
                assert f"{other} hand" not in cap.text and f"{other} arm" not in cap.text
    subjects = {
        get_family("walk")
        .captions(get_family("walk").sample(np.random.default_rng(s)), np.random.default_rng(s), False)[0]
        .text.split(" walk")[0]
        for s in range(40)
    }
    assert len(subjects) >= 4  # "a person", "someone", "a man", ...
