"""``python -m luckyao``: the command line of the workflow steps."""

import sys

from .cli import main

sys.exit(main())
