import sys

from pin_match.cli import main

sys.exit(main())
