"""`python -m gonio_cli ARGS`: the `gonio` console script without its installed wrapper."""

import sys

from gonio_cli.main import main

sys.exit(main())
