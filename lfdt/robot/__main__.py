"""``python -m lfdt.robot``: see :mod:`lfdt.robot.cli`."""

import sys

try:
    from lfdt.robot.cli import main
except KeyboardInterrupt:  # Ctrl-C while the modules load: the same one line as later on
    print("interrupted", file=sys.stderr)
    sys.exit(130)  # cli.EXIT_INTERRUPTED, which did not load

sys.exit(main())
