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
