"""``python -m sa_daemon.cli``."""

import sys

from .main import main

sys.exit(main())
