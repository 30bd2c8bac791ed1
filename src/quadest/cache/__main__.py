"""``python -m quadest.cache info|clear``, the same as ``quadest-cache info|clear``."""

import sys

from quadest.cache.cli import main

sys.exit(main())
