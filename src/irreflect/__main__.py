"""``python -m irreflect ...`` (the same as the ``irreflect`` script)."""

import sys

from .cli import main

sys.exit(main())
