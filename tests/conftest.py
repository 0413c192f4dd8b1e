import os
import signal
import sys

sys.path.insert(0, os.path.dirname(__file__))

# The Ctrl-C tests (test_checkpoint.py) send SIGINT to this process and expect Python's
# KeyboardInterrupt. A shell that starts the suite in the background (`make test &` in a
# script) makes it ignore SIGINT, which Python keeps, and tfm rightly leaves an ignored
# signal alone: 8 of those tests then failed. Restore Python's own handler for the suite.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
