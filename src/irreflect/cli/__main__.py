"""``python -m irreflect.cli ...`` (the same as the ``irreflect`` script)."""

import sys

from . import main

sys.exit(main())
