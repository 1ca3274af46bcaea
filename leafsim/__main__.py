import sys

from leafsim.cli import main

sys.exit(main())
