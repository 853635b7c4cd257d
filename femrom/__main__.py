import sys

from femrom.cli import main

sys.exit(main())
