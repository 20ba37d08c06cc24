import sys

from imagemap.cli import main

sys.exit(main())
