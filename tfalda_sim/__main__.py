"""``python -m tfalda_sim …`` is ``tfalda-sim …``."""

import sys

from tfalda_sim.cli import console_main

sys.exit(console_main())
