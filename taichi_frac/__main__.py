import os
import sys

from .cli import main

code = main()
if code == 130:
    # Under ``python -m``, a Ctrl-C that landed in code run through exec() (a dataclass being
    # made while the modules load) leaves CPython's "unhandled KeyboardInterrupt" mark set,
    # which turns the exit status into death by SIGINT: exit here, the run already stopped.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
sys.exit(code)
