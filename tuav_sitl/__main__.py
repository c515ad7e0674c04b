"""``python -m tuav_sitl``."""

import sys

from tuav_sitl.cli import main

sys.exit(main())
