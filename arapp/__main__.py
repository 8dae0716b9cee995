import sys

from arapp.cli import main

sys.exit(main())
