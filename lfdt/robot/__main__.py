"""``python -m lfdt.robot``: see :mod:`lfdt.robot.cli`."""

import sys

from lfdt.robot.cli import main

sys.exit(main())
