"""Imported first by a matrix stage's forkserver (:func:`lfdt.parallel.run_jobs` puts it at the head of the preload
list): from then on a Ctrl-C ends the server at once and silently, with exit code 130.

Python 3.11's forkserver imports its preload modules (torch, MuJoCo, MLflow: seconds) before it protects itself from
SIGINT, so a Ctrl-C in those seconds printed the server's traceback beside the stage's one line
(``error: interrupted ...``). The server passes this handler on to the workers it forks, which take Python's own
back once they start (:func:`lfdt.parallel._init_worker`): a worker's job ends on Ctrl-C as the stage does.
"""

import os
import signal


def _exit_quietly(signum: int, frame: object) -> None:
    os._exit(128 + signum)


signal.signal(signal.SIGINT, _exit_quietly)
