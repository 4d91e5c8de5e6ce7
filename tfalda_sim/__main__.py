import sys

from tfalda_sim.cli import main

sys.exit(main())
