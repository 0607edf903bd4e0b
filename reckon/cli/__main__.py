import sys

from reckon.cli import main

sys.exit(main())
