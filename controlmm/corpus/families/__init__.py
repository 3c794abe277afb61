"""Motion families, one module per group; importing this package registers them all.

The import order below is the registry order (travelling first, compositions last).
"""

from controlmm.corpus.families import walking  # noqa: F401,I001
from controlmm.corpus.families import turning  # noqa: F401
from controlmm.corpus.families import jumping  # noqa: F401
from controlmm.corpus.families import lowering  # noqa: F401
from controlmm.corpus.families import gestures  # noqa: F401
from controlmm.corpus.families import reaching  # noqa: F401
from controlmm.corpus.families import combos  # noqa: F401
