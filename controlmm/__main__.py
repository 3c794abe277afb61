import sys

from controlmm.cli.main import main

sys.exit(main())
