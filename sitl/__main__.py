"""``python -m sitl``: run the SITL vehicle (see ``sitl.cli.sitl_main``)."""

import sys

from sitl.cli import sitl_main

sys.exit(sitl_main())
