"""``python -m railpaper`` is the ``railpaper`` command."""

import sys

from railpaper.cli import main

sys.exit(main())
