"""``python -m tactile_dock_ros.tools.bench SUITE ...``: see the package docstring."""

import sys

from tactile_dock_ros.tools.bench import main

sys.exit(main())
