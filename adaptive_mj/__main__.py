import sys

from adaptive_mj.cli import main

sys.exit(main())
