"""``python -m rigctl``: the same as the ``rigctl`` command."""

import sys

from rigctl.cli.main import main

sys.exit(main())
