"""``python -m tfalda_sim …`` is ``tfalda-sim …``."""

import sys

from tfalda_sim.cli import main

sys.exit(main())
