import sys

from slamrel.cli import main

sys.exit(main())
