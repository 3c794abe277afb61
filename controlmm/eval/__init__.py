"""Evaluation: the spatial-control protocol, text-motion quality (FID, R-precision, ...) with its
evaluator, and probe runs on corpora and models (the probes themselves: :mod:`controlmm.corpus.probes`)."""
