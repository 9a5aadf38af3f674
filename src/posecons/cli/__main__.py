"""``python -m posecons.cli``: what ``train --devices N`` runs under torchrun."""

import sys

from . import main

sys.exit(main())
