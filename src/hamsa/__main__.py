"""``python -m hamsa``: the command-line interface (same as the ``hamsa`` command)."""

import sys

from hamsa.cli import main

sys.exit(main())
