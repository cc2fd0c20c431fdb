"""``python -m openel_async.cli``: the same as the ``openel-async`` command."""

import sys

from . import main

sys.exit(main())
