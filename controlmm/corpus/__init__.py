"""Procedural motion corpus with matching captions, in HumanML3D format.

Motions are planned, not captured: foot placement along a root path plus two-bone IK for
the legs, forward kinematics for the spine and head, IK towards gesture targets for the
arms, all on the HumanML3D reference skeleton (:mod:`controlmm.corpus.rig`). Each family
(:mod:`controlmm.corpus.families`) samples parameters, builds the joints and writes
captions whose words state those parameters (:mod:`controlmm.corpus.text`).

Public API::

    from controlmm.corpus import CorpusConfig, write_corpus, family_names, get_family
    write_corpus("corpus", CorpusConfig(clips=5000, seed=0))
"""

from controlmm.corpus.dataset import CorpusConfig, make_clip, plan_clips, write_corpus
from controlmm.corpus.family import Family
from controlmm.corpus.registry import family_names, get_family

__all__ = ["CorpusConfig", "Family", "family_names", "get_family", "make_clip", "plan_clips", "write_corpus"]
