import sys

from pin_match.cli.main import main

sys.exit(main())
