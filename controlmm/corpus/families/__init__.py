"""Motion families, one module per group, each holding its families in ``FAMILIES``.

The registry (:mod:`controlmm.corpus.registry`) lists the modules; its order is the registry order
(travelling first, compositions last).
"""
