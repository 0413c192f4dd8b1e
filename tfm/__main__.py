"""`python -m tfm` = the `tfm` command."""
import sys

from .cli import main

sys.exit(main())
