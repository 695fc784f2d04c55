"""``python -m gesturelib``: see :mod:`gesturelib.cli`."""

import sys

from gesturelib.cli import main

sys.exit(main())
