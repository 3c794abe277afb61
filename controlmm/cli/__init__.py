"""The ``controlmm`` command line: a thin layer over the library API."""

import time

STARTED = time.perf_counter()
"""The command's clock for its start-up: when the CLI package is first imported. The interpreter's
own start before it (a few hundredths of a second) is not counted; a process's start time in
``/proc`` is not used because it also counts what a shell did before exec'ing the command (in
``sh -c 'pip install ... && controlmm plan'`` the pip install)."""
