"""``python -m gcs.cli``."""

import sys

from gcs.cli import main

sys.exit(main())
