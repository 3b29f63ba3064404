"""A module whose import takes seconds, as torch's does: tests/test_parallel.py preloads it into a forkserver to
press Ctrl-C while the server is importing."""

import time

time.sleep(4)
