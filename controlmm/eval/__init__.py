"""Evaluation: geometric measures of motion and the text-adherence probes."""
