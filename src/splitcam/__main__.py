"""``python -m splitcam`` (also what ``torchrun -m splitcam`` runs)."""

import sys

from .cli import main

sys.exit(main())
