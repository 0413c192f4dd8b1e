"""``python -m tfm.paper``: the same as ``tfm paper``."""
from .cli import main

raise SystemExit(main())
