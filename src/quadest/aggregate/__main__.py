"""``python -m quadest.aggregate SWEEP_DIR``, the same as ``quadest-aggregate SWEEP_DIR``."""

import sys

from quadest.aggregate.cli import main

sys.exit(main())
