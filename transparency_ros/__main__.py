"""``python -m transparency_ros`` is the ``transparency`` command."""

import sys

from transparency_ros.cli import main

sys.exit(main())
