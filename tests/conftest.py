"""What every test shares.

pytest-xdist starts its worker processes with ``COLUMNS=80`` and ``LINES=24`` in their environment. The command
line's rich consoles are made when their modules are imported, and a console made while ``COLUMNS`` is set keeps
that width for good, so the tests that give the CLI a wide terminal (``env={"COLUMNS": ...}``) would see it cut at
80 columns in a worker and not in a single process. Without the variables a console asks for the width each time
it prints, as it does outside the tests.
"""

import os

for _name in ("COLUMNS", "LINES"):
    os.environ.pop(_name, None)

# `vfinfer infer` builds a missing reach ensemble on first use (2,000 simulations, minutes): a test that wants
# one sets the variable back and points VFINFER_CACHE_DIR at its own folder, never the user's cache.
os.environ["VFINFER_REACH_BUILD"] = "0"
