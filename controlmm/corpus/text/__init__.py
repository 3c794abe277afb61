"""Captions: templates with synonym slots and held-out phrasings, and a small POS tagger."""
