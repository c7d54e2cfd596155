"""``python -m verify.cli``: the ``totems`` command."""

import sys

from verify.cli.commands import main

sys.exit(main())
