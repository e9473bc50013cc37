"""``python -m benchmarks NAME [ARGS...] [--table PATH]``: see :mod:`benchmarks.runner`."""

import sys

from benchmarks.runner import main

sys.exit(main())
